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

from replay.models.kinematic import rotation as _rotation
from replay.util.errors import ReplayError

from .fusion_inputs import configured, field_channel

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
    return _rotation(att[:, 0], att[:, 1], att[:, 2])


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
    """(values in the body frame, note) of an IMU's ``gyro`` or ``attitude`` mounted with the rotation
    R_m of :func:`mount_rotation` (the sensor's axes in the body frame, the static transform
    base_link -> imu_link, robot_localization's use of it): omega_body = R_m omega_imu,
    R_world_body = R_world_imu R_m'. Neither declared nor recorded: as recorded (noted)."""
    mount, how = mount_rotation(entry)
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
    return out, f"task fusion: {key} {fld}: {how}: rotated into the body frame"


def _recorded(m) -> str:
    return f"/tf_static {m.parent} -> {m.child}"


def mount_rotation(entry):
    """([roll, pitch, yaw] of the sensor in the body frame, or None; how it was chosen): the declared
    ``mount`` wins over the recording's ``/tf_static`` (a disagreement beyond 1 mrad is said)."""
    rec = entry.recorded_mount
    if entry.mount is None:
        if rec is None:
            return None, ""
        return list(rec.rotation), f"mount from {_recorded(rec)} = {[round(v, 9) + 0.0 for v in rec.rotation]}"
    how = f"mount = {list(entry.mount)} declared"
    if rec is not None:
        a, b = rotation(np.array([entry.mount, rec.rotation], float))
        gap = np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1))
        if gap > 1e-3:
            said = [round(v, 9) + 0.0 for v in rec.rotation]
            how += f" (it differs from {_recorded(rec)} = {said} by {gap:.3g} rad; declared wins)"
    return list(entry.mount), how


def lever_arm(frame, entry, vals, valid, heading, key):
    """(fixes moved to the body origin, their validity, note) of a GPS input whose antenna sits at
    ``l`` in the body frame (declared ``lever_arm``, else the recording's ``/tf_static``), as
    robot_localization corrects a fix: p_body = p_antenna - R(roll, pitch, yaw) l, the attitude
    being the body's at the fix. ``heading``: (attitude values (n, 3) in the body frame, their
    validity, what they are) of a fused attitude input, or None: then the lever arm is not applied
    (the heading is unknown; said). A fix without an attitude within 0.5 s is not used (counted)."""
    rec = entry.recorded_mount
    if entry.lever_arm is not None:
        arm, how = np.asarray(entry.lever_arm, float), f"lever_arm = {list(entry.lever_arm)} declared"
        if rec is not None and np.linalg.norm(np.subtract(rec.translation, arm)) > 1e-3:
            how += f" (it differs from {_recorded(rec)} = {[round(v, 6) for v in rec.translation]}; declared wins)"
    elif rec is not None:
        arm, how = np.asarray(rec.translation, float), f"lever arm from {_recorded(rec)} = "
        how += str([round(v, 6) for v in rec.translation])
    else:
        return vals, valid, None
    if heading is None:
        return (
            vals,
            valid,
            (
                f"task fusion: {key} position: {how} NOT applied: no fused attitude input gives the heading at the "
                f"fixes, so they stay the antenna's (up to {np.linalg.norm(arm):.3g} m off the body origin)"
            ),
        )
    att, att_ok, what = heading
    t = np.asarray(frame.t, float)
    idx = np.flatnonzero(att_ok)
    rows = np.flatnonzero(valid)
    out, ok = np.array(vals, float), np.array(valid, bool)
    if len(idx):  # the nearest attitude sample of each fix
        j = np.clip(np.searchsorted(t[idx], t[rows]), 0, len(idx) - 1)
        prev = np.clip(j - 1, 0, len(idx) - 1)
        j = np.where(np.abs(t[idx[prev]] - t[rows]) < np.abs(t[idx[j]] - t[rows]), prev, j)
        near = np.where(np.abs(t[idx[j]] - t[rows]) <= 0.5, idx[j], -1)
    else:
        near = np.full(len(rows), -1)
    lost = rows[near < 0]
    ok[lost] = False
    use, at = rows[near >= 0], near[near >= 0]
    a = np.asarray(att, float)[at]
    shift = np.einsum("kij,j->ki", rotation(a), arm)
    out[use, : min(3, out.shape[1])] -= shift[:, : min(3, out.shape[1])]
    note = f"task fusion: {key} position: {how}: moved to the body origin by the attitude of {what}"
    if len(lost):
        note += f"; {len(lost)} fixes without an attitude within 0.5 s not used"
    return out, ok, note


def heading_source(frame, found, where, absolute):
    """(attitude (n, 3) in the body frame, validity, what it is) of the first input that fuses an
    absolute attitude (its mount applied), or None: the heading a lever arm is turned by."""
    for entry in found:
        fuse = configured(entry, f"{where}: [channels] {entry.entry}", absolute)[0]
        name = field_channel(frame, entry, "attitude") if "attitude" in fuse else None
        if name is None:
            continue
        ch = frame.channels[name]
        vals = np.asarray(ch.values, float).reshape(len(frame.t), -1)
        if entry.spec.mount == "rotation":
            vals = mounted(entry, "attitude", vals, "")[0]
        return vals, ch.valid & np.isfinite(vals).all(axis=1), f"{entry.entry} ({entry.source})"
    return None
