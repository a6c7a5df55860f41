"""The field lists of a mapping entry for the fusion task (``fuse``, ``differential``): each
means one thing (docs/bags.md, "The fusion task"). Used where a mapping is read
(:mod:`replay.adapters.mapping`) and where the task reads the roles of any frame
(:func:`replay.tasks.fusion_inputs.configured`)."""

from __future__ import annotations

from replay.util.errors import ReplayError, shown

DIFFERENTIAL_FIELDS = ("position", "attitude")  # pose deltas: a body velocity, a body rate


def check_field_lists(fuse, differential, where: str) -> None:
    """An entry's declared ``fuse`` and ``differential`` lists (None: not declared) mean one thing:
    not empty, no field twice, only pose fields differential, no field both absolute and differential."""
    for key, fields in (("fuse", fuse), ("differential", differential)):
        if fields is not None and not fields:
            raise ReplayError(
                f"{where}: {key} = [] names no field: leave it out ("
                + (
                    'the role\'s default), or set role = "none" to keep the channel out of every task'
                    if key == "fuse"
                    else "no field is differential by default)"
                )
            )
        twice = next((f for i, f in enumerate(fields or ()) if f in fields[:i]), None)
        if twice is not None:
            raise ReplayError(f"{where}: {key} names {shown(twice)} twice (a field is fused once)")
    bad = [f for f in differential or () if f not in DIFFERENTIAL_FIELDS]
    if bad:
        raise ReplayError(
            f"{where}: differential {shown(bad[0])}: only pose fields are differential (position: deltas as "
            f"a body velocity, attitude: as body rates); fuse {shown(bad[0])} as it is"
        )
    both = [f for f in fuse or () if f in (differential or ())]
    if both:
        raise ReplayError(
            f"{where}: {shown(both[0])} is in both fuse and differential: a field is used one way "
            "(absolute in fuse, or as deltas in differential)"
        )


def frame_declarations(spec: dict, where: str, ref: bool) -> dict:
    """An entry's frame declarations for the fusion task (docs/bags.md): ``twist_frame`` (an
    Odometry's twist in its child frame, REP 105, or its parent's) and ``mount`` (an IMU's
    rotation in the body frame, [roll, pitch, yaw] rad); only on a [channels] entry."""
    out = {}
    if "twist_frame" in spec:  # an Odometry's twist: in its child frame (REP 105) or its parent's
        if ref or spec["twist_frame"] not in ("child", "parent"):
            raise ReplayError(
                f"{where}: twist_frame must be \"child\" or "
                f"\"parent\" on a [channels] entry (got {shown(spec['twist_frame'])})"
            )
        out["twist_frame"] = spec["twist_frame"]
    if "mount" in spec:  # an IMU's mounting: the rotation base_link -> sensor (roll, pitch, yaw; rad)
        m = spec["mount"]
        ok = (
            isinstance(m, list)
            and len(m) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in m)
        )
        if ref or not ok or not all(abs(float(v)) < 10 for v in m):
            raise ReplayError(
                f"{where}: mount must be [roll, pitch, yaw] (rad, "
                f"the sensor's rotation in the body frame) on a [channels] entry (got {shown(m)})"
            )
        out["mount"] = [float(v) for v in m]
    return out
