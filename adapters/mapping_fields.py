"""The frame declarations of a mapping entry for the fusion task (``twist_frame``, ``mount``, ``lever_arm``;
docs/bags.md, "The fusion task"); its field lists are checked by
:func:`replay.roles.check_field_lists`, as the task checks the roles of any frame."""

from __future__ import annotations

from replay.util.errors import ReplayError, shown


def frame_declarations(spec: dict, where: str, ref: bool) -> dict:
    """An entry's frame declarations for the fusion task (docs/bags.md): ``twist_frame`` (an
    Odometry's twist in its child frame, REP 105, or its parent's), ``mount`` (an IMU's
    rotation in the body frame, [roll, pitch, yaw] rad) and ``lever_arm`` (a GPS antenna's
    position in the body frame, [x, y, z] m); only on a [channels] entry."""
    out = {}
    if "twist_frame" in spec:  # an Odometry's twist: in its child frame (REP 105) or its parent's
        if ref or spec["twist_frame"] not in ("child", "parent"):
            raise ReplayError(
                f"{where}: twist_frame must be \"child\" or "
                f"\"parent\" on a [channels] entry (got {shown(spec['twist_frame'])})"
            )
        out["twist_frame"] = spec["twist_frame"]
    for key, limit, what in (
        ("mount", 10, "mount must be [roll, pitch, yaw] (rad, the sensor's rotation in the body frame)"),
        ("lever_arm", 100, "lever_arm must be [x, y, z] (m, the antenna's position in the body frame)"),
    ):  # a sensor's mounting: the static transform base_link -> sensor (replay.roles.Mount)
        if key not in spec:
            continue
        m = spec[key]
        ok = (
            isinstance(m, list)
            and len(m) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in m)
        )
        if ref or not ok or not all(abs(float(v)) < limit for v in m):
            raise ReplayError(f"{where}: {what} on a [channels] entry (got {shown(m)})")
        out[key] = [float(v) for v in m]
    return out
