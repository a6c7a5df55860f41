"""The inputs of the ``fusion`` task: which channel measures which state components.

Every sensor input of the frame (``Frame.roles``: :class:`replay.roles.SensorInput` records
declared in a bag mapping or detected from the message type; role ``none`` is never an input)
is read through its *fields* (the channels of one topic: ``position``, ``attitude``,
``velocity``, ``rate``, ``gyro``, ``depth``). By default a role fuses what its message type
carries for navigation (``Role.fuse``), as robot_localization's per-sensor ``*_config`` would
be set for it; a mapping entry may say otherwise (``fuse = [...]``, ``differential = [...]``,
``noise = {field = variance}``; ``docs/bags.md``).

A field maps to state components of the 2-D or 3-D kinematic state
(:mod:`replay.models.kinematic`) with a sign (depth = -up) and, for angles, a wrap: the role's
:class:`replay.roles.Field` (:func:`components`). A *differential* field (pose deltas of an odometry) becomes a
body-velocity (position) or a yaw-rate (attitude) measurement at the later message:
``v_body = R(yaw_prev)^T (p_k - p_prev) / (t_k - t_prev)``.
"""

from __future__ import annotations

import numpy as np

from replay import roles
from replay.roles import Component, SensorInput, check_field_lists
from replay.models.kinematic import rotation
from replay.util.angles import wrap
from replay.util.errors import ReplayError, shown

from . import source_of


def components(field: str, dims: int, role: str) -> tuple[Component, ...]:
    """``(channel column, state component, sign, angle)`` of a field of ``role`` in the 2-D or 3-D state."""
    return roles.get(role).components(field, dims)


def noise_param(role: str, field: str) -> str:
    """The task parameter (``r_*``) of a field's default variance."""
    return roles.get(role).field(field).noise


def field_channel(frame, entry: SensorInput, field: str) -> str | None:
    """The channel holding ``field`` of a role entry (its declared channel, or ``<entry>_<field>``,
    or the entry's primary channel when that is the field), or None."""
    for name in (entry.channels.get(field), f"{entry.entry}_{field}", entry.entry):
        ch = frame.channels.get(name) if name else None
        if ch is not None and (
            name == entry.channels.get(field)
            or str(ch.description).endswith(f" {field}")
            or name == f"{entry.entry}_{field}"
        ):
            return name
    return None


def has_absolute_position(found) -> bool:
    """Whether an input gives absolute positions (a gps or pose input, or a declared one)."""
    for entry in found:
        fuse = entry.fuse or entry.spec.fuse
        if "position" in fuse and "position" not in (entry.differential or ()):
            return True
    return False


def inputs(frame) -> list[SensorInput]:
    """Every sensor input of the frame (not role ``none``), roles in :data:`replay.roles.ROLES` order;
    an input of an unknown role refused in one line naming the frame's source."""
    try:
        return roles.ordered(frame.roles)
    except ReplayError as e:
        raise ReplayError(f"{source_of(frame)}: task fusion: {e}") from None


def configured(entry: SensorInput, where: str, absolute: bool = False) -> tuple[tuple, tuple, dict]:
    """(fused fields, differential fields, noise) of an entry: its declaration or the role's default.

    An IMU's attitude is fused by default only where no absolute position input exists (dead
    reckoning, where it is the only heading reference): beside GPS fixes in a projected frame
    its yaw is in the IMU's own world frame (magnetic north, an arbitrary start), as on
    robot_localization's test1.bag, where it differs from the course over ground by about
    150-180 degrees (``Role.fuse_beside_fixes``). Declare ``fuse = ["gyro", "attitude"]`` when it
    is east-north-up; an adapter that has checked it (Bohai: yaw against the course) marks it
    ``attitude_enu``."""
    role = entry.spec
    default = role.fuse
    if role.fuse_beside_fixes is not None and absolute and not entry.attitude_enu:
        default = role.fuse_beside_fixes
    known = roles.known_fields()
    for f in [*(entry.fuse or ()), *(entry.differential or ())]:
        if f not in known:
            raise ReplayError(f"{where}: unknown field {shown(f)} (known: {', '.join(known)})")
    check_field_lists(entry.fuse, entry.differential, where)  # as a mapping's are checked
    fuse = tuple(entry.fuse or default)
    diff = tuple(entry.differential or ())
    return tuple(f for f in fuse if f not in diff), diff, dict(entry.noise or {})


def differential(t, values, valid, attitude, field: str, where: str, body_rates: bool = False):
    """(rows, (m, 3) derived measurements) of a differential field: body velocity from position
    deltas (rotated by the previous message's attitude), or rates from attitude deltas: the
    Euler-angle deltas over dt (the yaw rate of a 2-D state), or with ``body_rates`` the body
    rates of the relative rotation R_prev' R_cur (its rotation vector over dt; a 3-D state's
    p, q, r are body rates, not Euler-angle rates)."""
    idx = np.flatnonzero(valid & np.isfinite(values).all(axis=1))
    if len(idx) < 2:
        raise ReplayError(f"{where}: a differential {field} needs at least 2 messages (got {len(idx)})")
    if field == "position" and attitude is None:  # the deltas are rotated into the body frame by it
        raise ReplayError(f"{where}: a differential position needs the input's attitude, which it lacks")
    prev, cur = idx[:-1], idx[1:]
    dt = (t[cur] - t[prev])[:, None]
    if field == "attitude" and body_rates:
        rel = np.einsum("kji,kjl->kil", *(rotation(*values[i].T) for i in (prev, cur)))
        vee = np.stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0], rel[:, 1, 0] - rel[:, 0, 1]], 1) / 2
        s = np.linalg.norm(vee, axis=1)
        angle = np.arctan2(s, (np.trace(rel, axis1=1, axis2=2) - 1) / 2)
        scale = np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 1.0)
        return cur, vee * scale[:, None] / dt
    if field == "attitude":
        return cur, wrap(values[cur] - values[prev]) / dt

    att = attitude[prev] if attitude is not None else np.zeros((len(prev), 3))
    R = rotation(att[:, 0], att[:, 1], att[:, 2])
    return cur, np.einsum("kji,kj->ki", R, values[cur] - values[prev]) / dt


def variance(frame, entry: SensorInput, label: str, fld: str, comps, noise: dict, n: int, valid, default: float):
    """(n, len(comps)) variance per step and component of a fused field (``label`` as declared,
    ``fld`` what it measures), how it was chosen (a note) and the same as a record (the manifest's
    ``task_noise``). Declared ``noise`` first; else the recorded covariance diagonal (the
    ``<entry>_<label>_var`` channel of the message's own covariance), an entry that is zero,
    negative, missing or marked ``-1`` (ROS: "not given", in element 0) replaced by ``default``
    and counted per message; else ``default``. A differential field takes no recorded covariance:
    it is that of the pose, not of its change."""
    if fld in noise:  # by what it measures (a differential position: noise.velocity)
        v = float(noise[fld])
        return np.full((n, len(comps)), v), f"declared {v:g}", {"source": "declared", "variance": v}
    param = f"{noise_param(entry.role, fld)} = {default:g}"
    out = np.full((n, len(comps)), default)
    recorded = entry.spec.recorded_covariance and label == fld
    rec = frame.channels.get(f"{entry.entry}_{label}_var") if recorded else None
    record = {"source": "default", "variance": default}
    if rec is None:
        why = "" if label == fld else " (differential: a recorded covariance is the pose's, not its change's)"
        return out, f"default {param}{why}", record
    raw = np.asarray(rec.values, float).reshape(n, -1)
    cols = raw[:, [c for c, *_ in comps]]
    good = rec.valid[:, None] & np.isfinite(cols) & (cols > 0) & (raw[:, :1] != -1)
    messages = int(valid.sum())
    bad = int((valid & ~good.all(axis=1)).sum())
    record = {"source": "recorded", "channel": rec.description, "messages": messages, "replaced": bad}
    if bad == messages:
        record.update(source="default", variance=default)
        return (
            out,
            f"default {param} (the recorded covariance of all {messages} messages is zero, negative or -1)",
            record,
        )
    how = "recorded covariance" + (
        f" ({bad} of {messages} messages had none usable: zero, negative, -1 or missing; {param} there)" if bad else ""
    )
    record["default"] = default
    return np.where(good, cols, default), how, record


def threshold(entry: SensorInput, label: str) -> float | None:
    """The entry's rejection threshold (Mahalanobis distance) of a field, or None (not gated)."""
    value = entry.rejection_threshold
    if isinstance(value, dict):
        value = value.get(label)
    return None if value is None else float(value)


def unconstrained(index, dims: int) -> list[str]:
    """What no measured state component constrains: "speed" (no position nor body velocity),
    "heading" (no position, attitude nor rate), given the measured components ``index``."""
    pos, speed, heading = ((0, 1), (3, 4), (2, 5)) if dims == 2 else ((0, 1), (6, 7), (5, 11))
    seen = set(int(i) for i in index)
    return [name for name, comps in (("speed", pos + speed), ("heading", pos + heading)) if not seen & set(comps)]
