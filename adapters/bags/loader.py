"""``load``: a recording and its mapping into a :class:`~replay.frame.Frame`; ``inspect``: what a recording holds."""

from __future__ import annotations

import difflib
import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from replay.adapters.geodesy import Geo, plausible_latlon
from replay.frame import Frame, Report
from replay.adapters.options import declare
from replay.util.errors import DataError, shown
from replay.util.params import Param

from .. import rosmsg
from ..mapping import Mapping, from_dict, load_mapping
from ..mapping_propose import propose
from . import estimates as recorded
from . import mounts, sources
from .channels import place_entries, read_sources
from .reading import read
from .recording import Recording, Topic

SIM_TIME_BEFORE_NS = 315_532_800 * 10**9  # 1980-01-01: earlier stamps are simulation time


def resolve_mapping(mapping) -> Mapping | None:
    if mapping is None or isinstance(mapping, Mapping):
        return mapping
    if isinstance(mapping, dict):
        return from_dict(mapping)
    return load_mapping(mapping)


@dataclass(frozen=True)
class MappingParam(Param):
    """The ``mapping`` option: a mapping file (a path), a dict of the same form or a Mapping."""

    def accepts(self) -> str:
        return "a mapping file (a path), a dict of the same form or a Mapping" + (" (or null)" if self.optional else "")

    def _coerce(self, v):
        if isinstance(v, (dict, Mapping)):
            return True, v
        return super()._coerce(v)


CONVERSIONS = ("water_density", "atmospheric_pressure", "gravity")  # the mapping's [params]


@declare(
    "bags",
    MappingParam(
        "mapping", os.PathLike, None, "topic mapping (docs/bags.md; null: proposed from the topics)", optional=True
    ),
    Param(
        "time",
        str,
        None,
        "time axis: header (header.stamp) or log (receive time); null: the mapping's",
        choices=("header", "log"),
        optional=True,
    ),
    Param(
        "until",
        float,
        None,
        "only messages logged within this many s of the first one (null: the mapping's)",
        unit="s",
        low=0.0,
        low_open=True,
        optional=True,
    ),
    Param(
        "allow_truncated", bool, None, "use what precedes a truncation, flagged (null: the mapping's)", optional=True
    ),
    Param(
        "water_density",
        float,
        None,
        f"water density of the depth conversion (null: the mapping's, else {rosmsg.WATER_DENSITY:g})",
        unit="kg/m^3",
        low=0.0,
        low_open=True,
        optional=True,
    ),
    Param(
        "atmospheric_pressure",
        float,
        None,
        f"atmospheric pressure of the depth conversion (null: the mapping's, else {rosmsg.ATMOSPHERIC_PRESSURE:g})",
        unit="Pa",
        low=0.0,
        low_open=True,
        optional=True,
    ),
    Param(
        "gravity",
        float,
        None,
        f"gravity of the depth conversion (null: the mapping's, else {rosmsg.GRAVITY:g})",
        unit="m/s^2",
        low=0.0,
        low_open=True,
        optional=True,
    ),
)
def load(path, *, mapping, time, until, allow_truncated, **conversions) -> Frame:
    """Read a bag or MCAP into a Frame (see the module docstring).

    ``mapping``: a mapping file path, a dict of the same form, or None (proposed).
    ``time``, ``until``, ``allow_truncated`` and the conversion parameters
    (water_density, atmospheric_pressure, gravity) override the mapping's.
    """
    params = {k: v for k, v in conversions.items() if v is not None}
    path = Path(path).expanduser()
    mp = resolve_mapping(mapping)
    proposed = []

    def choose(listing):  # no mapping: propose one from the topic list
        proposed.append(propose(listing))
        if not proposed[0].entries:
            tf = [t for t, (typ, _) in listing.items() if rosmsg.kind_of(typ) == "tf"]
            raise DataError(
                path,
                "no topic of a supported type to map; write a mapping "
                "(see `replay inspect` and docs/bags.md)"
                + (
                    f"; {', '.join(tf)} hold(s) TF: name a pair in the mapping "
                    '(e.g. position = { topic = "/tf", frame = "odom", child = "base_link" })'
                    if tf
                    else ""
                ),
            )
        return proposed[0].topics

    until = until if until is not None else (mp.until if mp else None)
    rec = read(path, mounts.with_static(mp.topics if mp else choose), until)
    mp = mp or proposed[0]
    time = time or mp.time
    if time not in ("header", "log"):
        raise DataError(path, f"time must be 'header' or 'log' (got {shown(time)})")
    allow = mp.allow_truncated if allow_truncated is None else bool(allow_truncated)
    opts = {**mp.params, **params}
    report = Report()
    _fail_if_truncated(rec, report, allow)
    return build_frame(rec, mp, time, opts, report, until)


def _fail_if_truncated(rec: Recording, report, allow) -> None:
    if rec.truncated is None:
        return
    if not allow:
        raise DataError(
            rec.path,
            f"truncated or corrupted: {rec.truncated}; "
            f"{rec.read_messages} message(s) before it could be read — set "
            "allow_truncated = true in the mapping to use them (flagged)",
        )
    if report is not None:
        report.add(
            "flagged",
            str(rec.path),
            rec.read_messages,
            f"TRUNCATED recording: only the messages before the damage were read ({rec.truncated})",
        )


def _check_topics(rec: Recording, mp: Mapping) -> None:
    for e in mp.entries + mp.estimates:
        topic = rec.topics.get(e.topic)
        if topic is None:
            close = difflib.get_close_matches(e.topic, list(rec.topics), n=1)
            hint = f" (did you mean {close[0]}?)" if close else f" (topics: {', '.join(rec.topics)})"
            what = f"estimate {e.name}" if e.estimate else e.name
            raise DataError(rec.path, f"topic {e.topic} (mapped to {what}) is not in the recording{hint}")
        if rosmsg.kind_of(topic.type) is None:
            raise DataError(
                rec.path,
                f"topic {e.topic} has type {topic.type}, which no converter reads "
                f"(supported: {', '.join(sorted(rosmsg.KINDS))})",
            )
        if e.type and rosmsg.normalize_type(e.type) != topic.type:
            raise DataError(rec.path, f"topic {e.topic}: the mapping expects {e.type}, the recording has {topic.type}")
        if not topic.msgs:
            span = " within `until`" if mp.until or rec.truncated else ""
            raise DataError(rec.path, f"topic {e.topic} (mapped to {e.name}) has no messages{span}")


def build_frame(rec: Recording, mp: Mapping, time: str, opts: dict, report: Report, until: float | None) -> Frame:
    _check_topics(rec, mp)
    geo = _projection(rec, mp)
    srcs = read_sources(rec, mp, time, geo, opts)
    axis = np.unique(np.concatenate(list(srcs.stamps.values())))
    t0 = int(axis[0])
    sim = t0 < SIM_TIME_BEFORE_NS
    placed = place_entries(rec, mp, time, srcs, axis, report)
    _report_axis(report, srcs.stamps, len(axis), time, t0, sim)
    estimates = recorded.build(rec, mp, time, geo, t0, report, _reference_span(mp, srcs.stamps))
    meta = _frame_meta(rec, mp, time, t0, sim, until, estimates, geo)
    epoch = None if sim else t0 / 1e9
    roles = mounts.attach(rec, mp, placed.roles, srcs.frames, srcs.kinds, report)  # /tf_static
    return Frame((axis - t0) / 1e9, placed.channels, placed.reference, epoch, meta, report, estimates, roles)


def _projection(rec: Recording, mp: Mapping) -> Geo | None:
    """The projection: the first mapped NavSatFix topic's."""
    for topic_name in mp.topics:
        if rosmsg.kind_of(rec.topics[topic_name].type) == "navsatfix":
            return _make_geo(rec, rec.topics[topic_name])
    return None


def _report_axis(report: Report, stamps: dict, n: int, time: str, t0: int, sim: bool) -> None:
    shared = sum(len(s) for s in stamps.values()) - n
    report.add(
        "info",
        "t",
        n,
        f"union of the {time} stamps of {len(stamps)} mapped topic(s)"
        + (f"; {shared} stamp(s) shared by several topics" if shared else ""),
    )
    if sim:
        report.add("info", "t", n, f"simulation time: stamps start at {t0 / 1e9:.3f} s; epoch unknown")


def _reference_span(mp: Mapping, stamps: dict) -> tuple[int, int] | None:
    refs = [stamps[sources.key(e)] for e in mp.entries if e.reference]
    return (min(int(s[0]) for s in refs), max(int(s[-1]) for s in refs)) if refs else None


def _frame_meta(rec: Recording, mp: Mapping, time, t0, sim, until, estimates, geo) -> dict:
    meta = {
        "adapter": "bags",
        "source": str(rec.path),
        "format": rec.format,
        "time": time,
        "t0_ns": t0,
        "sim_time": bool(sim),
        "until": until,
        "truncated": rec.truncated,
        "sha256": _sha256(rec.path),
        "mapping": json.loads(json.dumps(_mapping_dict(mp))),
        "estimates": recorded.meta(estimates),
        "topics": {k: {"type": v.type, "count": v.count, "read": len(v.msgs)} for k, v in rec.topics.items()},
    }
    if geo is not None:
        meta.update(geo.meta())
    return meta


def _make_geo(rec: Recording, topic: Topic) -> Geo:
    lat = np.array([m.latitude for m in topic.msgs], float)
    lon = np.array([m.longitude for m in topic.msgs], float)
    alt = np.array([m.altitude for m in topic.msgs], float)
    status = np.array([m.status.status if hasattr(m, "status") else 0 for m in topic.msgs])
    ok = (status >= 0) & np.isfinite(alt) & plausible_latlon(lat, lon)
    if not ok.any():
        raise DataError(rec.path, f"topic {topic.name}: no valid fix (every status < 0 or lat/lon impossible)")
    return Geo(lat, lon, alt, ok)


def _mapping_dict(mp: Mapping) -> dict:
    return {
        "time": mp.time,
        "until": mp.until,
        "source": mp.source,
        "params": mp.params,
        "entries": [e.__dict__ for e in mp.entries],
        "estimates": [e.__dict__ for e in mp.estimates],
    }


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    files = [path] if path.is_file() else sorted(p for p in path.iterdir() if p.is_file())
    for p in files:
        with open(p, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    return h.hexdigest()


def inspect(path) -> dict:
    """Topics (type, count, rate, span by log time), the recording span and a proposed mapping."""
    rec = read(path, None, first_only=True)
    rows = []
    for t in rec.topics.values():
        log = np.asarray(t.log_ns, np.int64)
        span = (log[-1] - log[0]) / 1e9 if len(log) > 1 else 0.0
        rate = (len(log) - 1) / span if span > 0 else float("nan")
        stamp0 = None
        if t.msgs and hasattr(t.msgs[0], "header"):
            stamp0 = rosmsg.stamp_ns(t.msgs[0]) / 1e9
        rows.append(
            {
                "topic": t.name,
                "type": t.type,
                "count": t.count,
                "rate_hz": rate,
                "span_s": span,
                "supported": rosmsg.kind_of(t.type) is not None,
                "first_stamp_s": stamp0,
                "first_log_s": log[0] / 1e9 if len(log) else None,
            }
        )
    span = (rec.end_ns - rec.start_ns) / 1e9 if rec.start_ns is not None else 0.0
    mp = propose({t.name: (t.type, t.count) for t in rec.topics.values()})
    return {
        "path": str(rec.path),
        "format": rec.format,
        "start_ns": rec.start_ns,
        "span_s": span,
        "messages": sum(t.count for t in rec.topics.values()),
        "topics": rows,
        "truncated": rec.truncated,
        "mapping": mp,
    }
