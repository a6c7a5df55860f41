"""The frame of an odometry's twist, decided once and said (the ``fusion`` task, issue 34 item 1).

REP 105: a nav_msgs/Odometry's twist is in its ``child_frame_id`` (the body), its pose in
``header.frame_id`` (the parent, e.g. ``odom``). Some drivers leave ``child_frame_id`` empty
and publish the twist in the parent frame; read as body velocity, such a twist bends and
shrinks the dead-reckoned track without any error. So, for a fused ``velocity`` or ``rate``
of an Odometry entry:

* ``twist_frame = "child"`` declared on the mapping entry: the twist is the body's, as is;
* ``twist_frame = "parent"`` declared: the twist is rotated into the body frame by the
  message's own orientation, ``v_body = R(roll, pitch, yaw)' v_parent`` (angular velocity too);
* nothing declared: the ``child_frame_id`` must be set;

and the data must not contradict the frame declared (or the child frame, undeclared):
:func:`evident_frame` compares the twist, read either way, with the pose's own course; a
contradiction is refused in one line naming the topic and the key.

Every decision is a task note.
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import ReplayError

from .fusion_inputs import field_channel

HOW = 'declare twist_frame = "child" (body) or "parent" (header frame) on the mapping entry'


def twist_in_body(frame, entry, fld, vals, valid, where, key):
    """(values in the body frame, note) of an Odometry entry's fused ``velocity`` or ``rate``."""
    name = field_channel(frame, entry, fld)
    child = str(frame.channels[name].frame or "").strip("/")
    declared = entry.twist_frame
    topic = entry.source
    pos, att = (frame.channels.get(field_channel(frame, entry, f) or "") for f in ("position", "attitude"))
    if declared is None and not child:
        raise ReplayError(
            f"{where}: {key}: {topic} has an empty child_frame_id, so its twist's frame is unknown "
            f"(REP 105: the child frame); {HOW}"
        )
    shown = evident_frame(frame.t, pos, att, vals, valid) if fld == "velocity" else None
    if shown is not None and shown != (declared or "child"):
        said = f"twist_frame = {declared!r} is declared" if declared else f"its child_frame_id is {child!r}"
        follows = "body axis" if shown == "child" else "pose course in the parent frame"
        raise ReplayError(f"{where}: {key}: {topic}'s twist follows the {follows}, but {said}; {HOW}")
    if declared != "parent":
        how = "twist_frame = child declared" if declared else f"twist in child_frame_id {child!r} (REP 105)"
        return vals, f"task fusion: {key} {fld}: {how}: the body frame, as recorded"
    if att is None:
        raise ReplayError(f"{where}: {key}: twist_frame = parent needs the message's orientation ({topic})")
    a = np.asarray(att.values, float)
    ok = valid & att.valid & np.isfinite(a).all(axis=1)
    out = np.full(vals.shape, np.nan)
    out[ok] = np.einsum("kji,kj->ki", rotation(a[ok]), vals[ok])  # R' v: parent -> body
    return out, (
        f"task fusion: {key} {fld}: twist_frame = parent declared: rotated from the parent frame into the "
        "body frame by each message's orientation"
    )


def rotation(att):
    from replay.models.kinematic import rotation as r

    return r(att[:, 0], att[:, 1], att[:, 2])


def evident_frame(t, pos, att, vel, valid, min_speed=0.2):
    """The frame the pose's own motion shows the twist is in, ``"child"`` or ``"parent"``, or None
    (undecidable: no pose, a pose at rest, a heading near 0 where both readings agree): over
    consecutive messages moving at least ``min_speed``, the course velocity dp/dt is matched by one
    reading (the twist as recorded: parent; rotated from the body: child) at least 3 times better
    in RMS than by the other, which misses it by at least 30 % of the speed."""
    if pos is None or att is None:
        return None
    p, a, v = (np.asarray(c, float) for c in (pos.values, att.values, vel))
    ok = valid & pos.valid & att.valid & np.isfinite(p[:, :2]).all(1) & np.isfinite(a).all(1) & np.isfinite(v).all(1)
    idx = np.flatnonzero(ok)
    if len(idx) < 10:
        return None
    prev, cur = idx[:-1], idx[1:]
    dt = np.asarray(t, float)[cur] - np.asarray(t, float)[prev]
    course = (p[cur, :2] - p[prev, :2]) / np.where(dt > 0, dt, np.nan)[:, None]
    speed = np.linalg.norm(course, axis=1)
    moving = np.isfinite(speed) & (speed >= min_speed)
    if moving.sum() < 10:
        return None
    body = np.einsum("kij,kj->ki", rotation(a[prev]), v[prev])[:, :2]
    miss = {
        "child": np.sqrt(np.mean(np.sum((body - course) ** 2, axis=1)[moving])),
        "parent": np.sqrt(np.mean(np.sum((v[prev, :2] - course) ** 2, axis=1)[moving])),
    }
    scale = 0.3 * np.sqrt(np.mean(speed[moving] ** 2))
    for a_, b_ in (("child", "parent"), ("parent", "child")):
        if miss[b_] > 3 * miss[a_] and miss[b_] > scale:
            return a_
    return None


def imu_yaw_sense(frame, entry, att_vals, valid, where, key):
    """The note on a fused IMU attitude's convention, or a refusal in one line: its yaw (in the
    body frame, after any ``mount``) must turn the way its gyro's body z says (z up, REP 103's ENU
    and FLU). Over windows of about 1 s, the yaw's change and the integrated gyro z correlate
    below -0.5: a NED orientation (yaw clockwise from north) beside a z-up gyro, or the reverse,
    refused; above 0.5: ENU, noted; between, or their spreads more than 2 times apart (a gyro z
    that does not turn): undecided, noted (the sensor's axes may not be the body's: ``mount``)."""
    g = frame.channels.get(field_channel(frame, entry, "gyro") or "")
    if g is None:
        return f"task fusion: {key} attitude: no gyro beside it: its yaw convention (ENU) is not checked"
    gyro = mounted(entry, "gyro", np.asarray(g.values, float).reshape(len(frame.t), -1), key)[0]
    idx = np.flatnonzero(valid & g.valid & np.isfinite(gyro).all(axis=1) & np.isfinite(att_vals[:, 2]))
    t = np.asarray(frame.t, float)[idx]
    if len(idx) < 20 or t[-1] - t[0] < 10.0:
        return f"task fusion: {key} attitude: too few messages to check its yaw convention against the gyro"
    w = max(1, int(round(1.0 / np.median(np.diff(t)))))
    turned = np.concatenate([[0.0], np.cumsum((gyro[idx][1:, 2] + gyro[idx][:-1, 2]) / 2 * np.diff(t))])
    yaw = np.unwrap(np.asarray(att_vals, float)[idx, 2])
    dy, dg = yaw[w:] - yaw[:-w], turned[w:] - turned[:-w]
    scale = np.std(dy) / max(np.std(dg), 1e-300)  # near 1 when the gyro's z is the axis the yaw turns about
    c = float(np.corrcoef(dy, dg)[0, 1]) if 0.5 < scale < 2.0 else 0.0
    if c < -0.5:
        raise ReplayError(
            f"{where}: {key}: {entry.source}'s orientation yaw turns against its angular velocity about z "
            f"(correlation {c:.2f} over 1 s): a NED orientation (yaw clockwise from north) beside a z-up gyro, "
            'or the reverse; fuse = ["gyro"] only'
        )
    sense = "turns with" if c > 0.5 else "does not follow (undecided; mount = [roll, pitch, yaw] if not z up)"
    return f"task fusion: {key} attitude: its yaw {sense} the gyro's z (correlation {c:.2f} over 1 s)"


def mounted(entry, fld, vals, key):
    """(values in the body frame, note) of an IMU's ``gyro`` or ``attitude`` declared ``mount =
    [roll, pitch, yaw]`` (the sensor's rotation R_m in the body frame, as a static transform
    base_link -> imu_link, robot_localization's use of it): omega_body = R_m omega_imu,
    R_world_body = R_world_imu R_m'. Not declared: as recorded (noted)."""
    mount = None if entry.mount is None else list(entry.mount)
    if mount is None:
        return vals, f"task fusion: {key} {fld}: no mount declared: the sensor's axes are the body's"
    Rm = rotation(np.array([mount], float))[0]
    ok = np.isfinite(vals).all(axis=1)
    out = np.full(vals.shape, np.nan)
    if fld == "attitude":
        R = np.einsum("kij,lj->kil", rotation(vals[ok]), Rm)  # R_world_imu R_m'
        out[ok] = np.column_stack(
            [
                np.arctan2(R[:, 2, 1], R[:, 2, 2]),
                -np.arcsin(np.clip(R[:, 2, 0], -1, 1)),
                np.arctan2(R[:, 1, 0], R[:, 0, 0]),
            ]
        )
    else:
        out[ok] = vals[ok] @ Rm.T
    return out, f"task fusion: {key} {fld}: mount = {mount} declared: rotated into the body frame"
