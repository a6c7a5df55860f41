"""ROS (and Foxglove) messages -> arrays for frame channels.

One converter per supported message kind. A converter takes the list of
deserialized messages of one topic and returns ``{field: (values, valid, unit,
frame, components, angles, convention)}``; the adapter names the channels
``<name>`` for the kind's primary field and ``<name>_<field>`` for the others.

| kind | ROS types | primary field | other fields |
|---|---|---|---|
| imu | sensor_msgs/Imu | gyro (rad/s, body) | accel (m/s^2, body), attitude (roll, pitch, yaw; masked when orientation_covariance[0] = -1); gyro_var, accel_var, attitude_var |
| odometry | nav_msgs/Odometry | position (m, header.frame_id) | attitude, velocity (m/s, child_frame_id), rate (rad/s, child_frame_id); position_var, attitude_var, velocity_var, rate_var |
| navsatfix | sensor_msgs/NavSatFix, foxglove.LocationFix | position (east, north, up in m, local ENU from UTM) | sigma (sqrt of the covariance diagonal, m), status; position_var |
| pressure | sensor_msgs/FluidPressure | depth (m, positive down) | pressure (Pa) |
| twist | geometry_msgs/TwistStamped, TwistWithCovarianceStamped | velocity (m/s, header.frame_id) | rate (rad/s); velocity_var, rate_var (with covariance) |
| pose | geometry_msgs/PoseStamped, PoseWithCovarianceStamped, foxglove.PoseInFrame | position (m, frame_id) | attitude; position_var, attitude_var (with covariance) |
| tf | tf2_msgs/TFMessage, geometry_msgs/TransformStamped | one parent -> child pair, read as a pose (:func:`tf_pair`) | attitude |
| path | nav_msgs/Path | the poses of its last message, read as poses (:func:`path_poses`) | attitude |

``<field>_var``: the diagonal of the message's recorded covariance of that field (x, y, z or
roll, pitch, yaw; 6x6 pose and twist covariances split in two), raw: zero, negative and ``-1``
entries are kept for the fusion task to count and replace.

Attitude is (roll, pitch, yaw) in radians from the quaternion, ZYX (yaw about
z, then pitch about y, then roll about x), angles wrapped to (-pi, pi]; ``yaw``
is ROS's REP-103 heading: 0 = +x (east in an ENU frame), counter-clockwise
positive.

Depth from FluidPressure (REP: ``fluid_pressure`` in Pa):
``depth = (p - p_atm) / (rho * g)`` with ``water_density`` rho (kg/m^3),
``atmospheric_pressure`` p_atm (Pa) and ``gravity`` g (m/s^2) as parameters.
"""  # noqa: E501 (Markdown tables)

from __future__ import annotations

import numpy as np

KINDS = {
    "sensor_msgs/msg/Imu": "imu",
    "nav_msgs/msg/Odometry": "odometry",
    "sensor_msgs/msg/NavSatFix": "navsatfix",
    "sensor_msgs/msg/FluidPressure": "pressure",
    "geometry_msgs/msg/TwistStamped": "twist",
    "geometry_msgs/msg/TwistWithCovarianceStamped": "twist",
    "geometry_msgs/msg/PoseStamped": "pose",
    "geometry_msgs/msg/PoseWithCovarianceStamped": "pose",
    "foxglove.PoseInFrame": "pose",
    "foxglove.LocationFix": "navsatfix",
    "tf2_msgs/msg/TFMessage": "tf",
    "tf/msg/tfMessage": "tf",  # ROS 1's older tf (the same fields)
    "geometry_msgs/msg/TransformStamped": "tf",
    "nav_msgs/msg/Path": "path",
}
PRIMARY = {
    "imu": "gyro",
    "odometry": "position",
    "navsatfix": "position",
    "pressure": "depth",
    "twist": "velocity",
    "pose": "position",
    "tf": "position",
    "path": "position",
}

WATER_DENSITY = 1025.0  # kg/m^3, sea water
ATMOSPHERIC_PRESSURE = 101325.0  # Pa
GRAVITY = 9.80665  # m/s^2

RPY = ("roll", "pitch", "yaw")
RPY_CONVENTION = (
    "roll, pitch, yaw from the quaternion (ZYX); yaw: 0 = +x of the frame, counter-clockwise positive (REP-103)"
)
XYZ = ("x", "y", "z")


def normalize_type(msgtype: str) -> str:
    """'sensor_msgs/Imu' and 'sensor_msgs/msg/Imu' -> 'sensor_msgs/msg/Imu'."""
    parts = msgtype.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return msgtype


def kind_of(msgtype: str) -> str | None:
    return KINDS.get(normalize_type(msgtype))


def stamp_ns(msg) -> int:
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def frame_id(msgs) -> str:
    return str(msgs[0].header.frame_id) if msgs else ""


def quat_to_rpy(q: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions x, y, z, w -> (n, 3) roll, pitch, yaw (ZYX)."""
    x, y, z, w = q.T
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.column_stack([roll, pitch, yaw])


def rpy_to_quat(rpy: np.ndarray) -> np.ndarray:
    """(n, 3) roll, pitch, yaw -> (n, 4) quaternions x, y, z, w (inverse of quat_to_rpy)."""
    r, p, y = (np.asarray(rpy, float)[:, i] / 2 for i in range(3))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.column_stack(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ]
    )


def _vec(items) -> np.ndarray:
    return np.array([(v.x, v.y, v.z) for v in items], float).reshape(-1, 3)


def _quat(items) -> np.ndarray:
    return np.array([(q.x, q.y, q.z, q.w) for q in items], float).reshape(-1, 4)


def _variances(covs, size: int, first: int, unit: str, frame: str):
    """The recorded variances of one field: diagonal entries ``first, first + 1, first + 2`` of each
    message's row-major ``size`` x ``size`` covariance (3: an Imu's or a NavSatFix's; 6: a pose's or
    a twist's, rotations from 3), raw: 0, negative and ROS's ``-1`` ("not given") are kept, for
    the fusion task to count and replace; NaN where a message has no covariance of that size."""
    idx = [(first + i) * (size + 1) for i in range(3)]
    vals = np.array(
        [[c[i] for i in idx] if len(c) == size * size else (np.nan,) * 3 for c in (tuple(c) for c in covs)], float
    ).reshape(-1, 3)
    return _field(vals, unit, frame, np.isfinite(vals).all(axis=1), XYZ, (), "recorded covariance diagonal")


def _field(values, unit, frame="", valid=None, components=(), angles=(), convention=""):
    values = np.asarray(values, float)
    if valid is None:
        valid = np.isfinite(values) if values.ndim == 1 else np.isfinite(values).all(axis=1)
    return values, np.asarray(valid, bool), unit, frame, components, angles, convention


def _attitude(quats, frame, valid=None):
    q = _quat(quats)
    norm_ok = np.abs(np.linalg.norm(q, axis=1) - 1.0) < 1e-3
    ok = norm_ok if valid is None else (norm_ok & valid)
    return _field(quat_to_rpy(q), "rad", frame, ok, RPY, (0, 1, 2), RPY_CONVENTION)


def _pose_of(msg):
    """The geometry_msgs/Pose inside a PoseStamped / PoseWithCovarianceStamped / PoseInFrame."""
    pose = msg.pose
    return pose.pose if hasattr(pose, "pose") else pose


class _Pose:
    """A stamped pose made from a transform or a Path element (read like a PoseStamped)."""

    __slots__ = ("header", "pose")

    def __init__(self, header, position, orientation):
        self.header = header
        self.pose = _Plain(position=position, orientation=orientation)


class _Plain:
    def __init__(self, **kw):
        self.__dict__.update(kw)


def frame_name(name) -> str:
    """A TF frame name without ROS 1's leading '/'."""
    return str(name).strip("/")


def tf_pair(msgs: list, log_ns, parent: str | None, child: str | None):
    """The transforms ``parent`` -> ``child`` of TFMessage / TransformStamped messages, as poses.

    Returns (poses, log times of the messages holding them, every pair seen with its count).
    ``parent``/``child`` None (a TransformStamped topic): every transform.
    """
    poses, logs, seen = [], [], {}
    for msg, log in zip(msgs, log_ns):
        for tr in msg.transforms if hasattr(msg, "transforms") else [msg]:
            pair = (frame_name(tr.header.frame_id), frame_name(tr.child_frame_id))
            seen[pair] = seen.get(pair, 0) + 1
            if parent is None or pair == (parent, child):
                poses.append(_Pose(tr.header, tr.transform.translation, tr.transform.rotation))
                logs.append(log)
    return poses, logs, seen


def path_poses(msgs: list, log_ns):
    """The poses of the last nav_msgs/Path message (each with its own header), and its log time each."""
    if not msgs:
        return [], []
    last = list(msgs[-1].poses)
    return last, [log_ns[-1]] * len(last)


def convert(kind: str, msgs: list, geo=None, options: dict | None = None) -> dict:
    """Fields of ``msgs`` (all of one ``kind``); ``geo`` projects lat/lon (see bags.Geo)."""
    opt = options or {}
    fid = frame_id(msgs)
    if kind == "imu":
        cov0 = np.array([m.orientation_covariance[0] for m in msgs], float)
        return {
            "gyro": _field(_vec(m.angular_velocity for m in msgs), "rad/s", fid, components=XYZ),
            "accel": _field(_vec(m.linear_acceleration for m in msgs), "m/s^2", fid, components=XYZ),
            "attitude": _attitude([m.orientation for m in msgs], fid, cov0 != -1),
            "gyro_var": _variances([m.angular_velocity_covariance for m in msgs], 3, 0, "(rad/s)^2", fid),
            "accel_var": _variances([m.linear_acceleration_covariance for m in msgs], 3, 0, "(m/s^2)^2", fid),
            "attitude_var": _variances([m.orientation_covariance for m in msgs], 3, 0, "rad^2", fid),
        }
    if kind == "odometry":
        child = str(msgs[0].child_frame_id) if msgs else ""
        poses = [m.pose.pose for m in msgs]
        twists = [m.twist.twist for m in msgs]
        pcov, tcov = [m.pose.covariance for m in msgs], [m.twist.covariance for m in msgs]
        return {
            "position": _field(_vec(p.position for p in poses), "m", fid, components=XYZ),
            "attitude": _attitude([p.orientation for p in poses], fid),
            "velocity": _field(_vec(t.linear for t in twists), "m/s", child, components=XYZ),
            "rate": _field(_vec(t.angular for t in twists), "rad/s", child, components=XYZ),
            "position_var": _variances(pcov, 6, 0, "m^2", fid),
            "attitude_var": _variances(pcov, 6, 3, "rad^2", fid),
            "velocity_var": _variances(tcov, 6, 0, "(m/s)^2", child),
            "rate_var": _variances(tcov, 6, 3, "(rad/s)^2", child),
        }
    if kind == "pose":
        poses = [_pose_of(m) for m in msgs]
        out = {
            "position": _field(_vec(p.position for p in poses), "m", fid, components=XYZ),
            "attitude": _attitude([p.orientation for p in poses], fid),
        }
        if msgs and hasattr(msgs[0].pose, "covariance"):  # PoseWithCovarianceStamped
            pcov = [m.pose.covariance for m in msgs]
            out.update(
                position_var=_variances(pcov, 6, 0, "m^2", fid), attitude_var=_variances(pcov, 6, 3, "rad^2", fid)
            )
        return out
    if kind == "twist":
        twists = [m.twist.twist if hasattr(m.twist, "twist") else m.twist for m in msgs]
        out = {
            "velocity": _field(_vec(t.linear for t in twists), "m/s", fid, components=XYZ),
            "rate": _field(_vec(t.angular for t in twists), "rad/s", fid, components=XYZ),
        }
        if msgs and hasattr(msgs[0].twist, "covariance"):  # TwistWithCovarianceStamped
            tcov = [m.twist.covariance for m in msgs]
            out.update(
                velocity_var=_variances(tcov, 6, 0, "(m/s)^2", fid), rate_var=_variances(tcov, 6, 3, "(rad/s)^2", fid)
            )
        return out
    if kind == "pressure":
        p = np.array([m.fluid_pressure for m in msgs], float)
        rho = float(opt.get("water_density", WATER_DENSITY))
        p_atm = float(opt.get("atmospheric_pressure", ATMOSPHERIC_PRESSURE))
        g = float(opt.get("gravity", GRAVITY))
        depth = (p - p_atm) / (rho * g)
        return {"depth": _field(depth, "m", "down"), "pressure": _field(p, "Pa", fid)}
    if kind == "navsatfix":
        lat = np.array([m.latitude for m in msgs], float)
        lon = np.array([m.longitude for m in msgs], float)
        alt = np.array([m.altitude for m in msgs], float)
        status = np.array([m.status.status if hasattr(m, "status") else 0 for m in msgs], float)
        cov = np.array(
            [tuple(m.position_covariance)[::4] if len(m.position_covariance) == 9 else (np.nan,) * 3 for m in msgs],
            float,
        ).reshape(-1, 3)
        ok = (status >= 0) & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(alt)
        ok &= (np.abs(lat) <= 90) & (np.abs(lon) <= 180) & ~((lat == 0) & (lon == 0))
        enu = geo.forward(lat, lon, alt, ok)
        return {
            "position": _field(
                enu,
                "m",
                "ENU local",
                ok,
                ("east", "north", "up"),
                (),
                "UTM (meta crs) minus meta origin; up = altitude - origin altitude",
            ),
            "sigma": _field(np.sqrt(np.abs(cov)), "m", "ENU local", ok, ("east", "north", "up")),
            "position_var": _variances([m.position_covariance for m in msgs], 3, 0, "m^2", "ENU local"),
            "status": _field(status, "", "", np.ones(len(status), bool)),
        }
    raise ValueError(f"no converter for {kind}")
