"""The mapped entries of a bag as the frame's channels: one source per topic (and TF pair), each
entry's fields placed on the union time axis, its role for the tasks, and what the report says."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from replay import roles
from replay.frame import Channel, Report
from replay.util.errors import DataError, ReplayError

from .. import rosmsg
from ..mapping import Mapping, role_of
from . import mounts, sources
from .recording import Recording


@dataclass
class Sources:
    """Per source (sources.key): its stamps on the chosen time axis, its other time, converted fields, kind."""

    stamps: dict = field(default_factory=dict)
    other: dict = field(default_factory=dict)
    fields: dict = field(default_factory=dict)
    kinds: dict = field(default_factory=dict)
    frames: dict = field(default_factory=dict)  # (header.frame_id, child_frame_id): mounts.frames_of


@dataclass
class Placed:
    """The frame's channels and reference channels, the task roles, and who made each channel name."""

    other_name: str
    channels: dict = field(default_factory=dict)
    reference: dict = field(default_factory=dict)
    roles: list = field(default_factory=list)  # replay.roles.SensorInput, in the mapping's order
    made: dict = field(default_factory=dict)  # (group, channel name) -> the entry that made it


def read_sources(rec: Recording, mp: Mapping, time: str, geo, opts: dict) -> Sources:
    """One source per topic (and TF pair), shared by the entries reading it."""
    srcs = Sources()
    for e in mp.entries:
        src = sources.key(e)
        if src not in srcs.fields:
            msgs, logs, srcs.kinds[src] = sources.messages(rec, e)
            srcs.frames[src] = mounts.frames_of(msgs)
            srcs.stamps[src], srcs.other[src] = sources.stamps(rec, e, msgs, logs, time)
            srcs.fields[src] = rosmsg.convert(srcs.kinds[src], msgs, geo, opts)
    return srcs


def _name(e, kind: str, fname: str) -> str:
    return e.name if fname == rosmsg.PRIMARY[kind] else f"{e.name}_{fname}"


def _claim_names(mp: Mapping, e, keys: list, made: dict) -> None:
    for key in keys:
        maker = made.setdefault((e.reference, key), e.name)
        if maker != e.name:
            raise DataError(
                mp.source,
                f"[{'reference' if e.reference else 'channels'}] {e.name} "
                f"({e.topic}) makes channel {key}, which {maker} makes too: "
                "rename one of them",
            )


def _entry_channels(e, topic_type: str, fields: dict, kind: str, idx, n: int) -> dict:
    out = {}
    for fname, (vals, valid, unit, frame, comps, angles, conv) in fields.items():
        full = np.full((n,) + vals.shape[1:], np.nan)
        full[idx] = vals
        ok = np.zeros(n, bool)
        ok[idx] = valid
        out[_name(e, kind, fname)] = Channel(
            full, unit, frame, ok, tuple(comps), tuple(angles), conv, f"{e.topic}{e.pair} ({topic_type}) {fname}"
        )
    return out


def _other_time(e, other, idx, n: int, t0: int, other_name: str) -> Channel:
    t_other = np.full(n, np.nan)
    t_other[idx] = (other - t0) / 1e9
    return Channel(
        t_other,
        "s",
        "",
        np.isin(np.arange(n), idx),
        description=f"{e.topic} {other_name.replace('_', ' ')}, seconds from t = 0",
    )


def _role_row(mp: Mapping, e, topic_type: str, fields: dict, kind: str) -> roles.SensorInput | None:
    role = role_of(e, topic_type, mp.source)
    if not role or role == roles.NONE:
        return None
    names = {f: _name(e, kind, f) for f in roles.get(role).fields if f in fields}
    if "twist_frame" in e.fusion and kind != "odometry":
        raise ReplayError(f"{mp.source}: [channels] {e.name}: twist_frame is for an Odometry (not {topic_type})")
    if "mount" in e.fusion and kind != "imu":
        raise ReplayError(f"{mp.source}: [channels] {e.name}: mount is for an Imu (not {topic_type})")
    if "lever_arm" in e.fusion and roles.get(role).mount != "lever_arm":
        arms = ", ".join(r.name for r in roles.ROLES.values() if r.mount == "lever_arm")
        raise ReplayError(
            f"{mp.source}: [channels] {e.name}: lever_arm is for an antenna's fixes (role {arms}; not {role})"
        )
    for key, value in e.fusion.items():  # the fusion task's field lists: fields this message has
        if key in ("twist_frame", "mount", "lever_arm") or not isinstance(value, (list, tuple, dict)):
            continue
        for f in value:
            if f not in fields:
                raise ReplayError(
                    f"{mp.source}: [channels] {e.name}: {key} names {f!r}, which a "
                    f"{topic_type} lacks (it has: {', '.join(fields)})"
                )
    return roles.make_input(role, e.name, f"{e.topic} ({topic_type})", names, e.role is not None, **e.fusion)


def _report_entry(report: Report, e, topic_type: str, fields: dict, kind: str, m: int, n: int, time: str) -> None:
    primary = np.asarray(fields[rosmsg.PRIMARY[kind]][1], bool)
    report.add(
        "info",
        e.name,
        m,
        f"{e.topic} ({topic_type}): {m} messages at their {time} stamps; not valid at the other {n - m} samples",
    )
    if (~primary).any():
        report.add(
            "masked",
            e.name,
            int((~primary).sum()),
            f"{e.topic}: messages with no usable value (e.g. NavSatFix status < 0 / NO_FIX, "
            "NaN, unnormalised quaternion)",
        )
    for fname, (values, valid, *_) in fields.items():  # every other field's lost messages (NaN twist)
        lost = ~np.asarray(valid, bool)
        if fname == rosmsg.PRIMARY[kind] or not lost.any():
            continue
        if np.array_equal(lost, ~primary) and np.isfinite(np.asarray(values, float)[lost]).all():
            continue  # masked with its message only (a NO_FIX fix's sigma): the line above says it
        why = "NaN/inf, not a unit quaternion or declared unknown" if fname == "attitude" else "NaN or inf"
        report.add("masked", _name(e, kind, fname), int(lost.sum()), f"{e.topic}: {fname} {why} in these messages")


def place_entries(rec: Recording, mp: Mapping, time: str, srcs: Sources, axis, report: Report) -> Placed:
    """Every mapped entry's channels on ``axis`` (valid only at its own stamps), its role, its report lines."""
    t0, n = int(axis[0]), len(axis)
    placed = Placed("header_time" if time == "log" else "log_time")
    for e in mp.entries:
        topic_type = rec.topics[e.topic].type
        src = sources.key(e)
        kind, fields = srcs.kinds[src], srcs.fields[src]
        idx = np.searchsorted(axis, srcs.stamps[src])
        group = placed.reference if e.reference else placed.channels
        other_key = f"{e.name}_{placed.other_name}"
        _claim_names(mp, e, [_name(e, kind, f) for f in fields] + [other_key], placed.made)
        group.update(_entry_channels(e, topic_type, fields, kind, idx, n))
        group[other_key] = _other_time(e, srcs.other[src], idx, n, t0, placed.other_name)
        role = _role_row(mp, e, topic_type, fields, kind)
        if role is not None:
            placed.roles.append(role)
        _report_entry(report, e, topic_type, fields, kind, len(idx), n, time)
    return placed
