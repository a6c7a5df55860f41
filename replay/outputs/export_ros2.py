"""ROS 2 bags (MCAP storage, standard message types only) written from frames and runs.

* :func:`write_frame_bag` writes every mapped topic of a frame read by the
  ``bags`` adapter (``frame.meta["mapping"]``) back as its message type, at the
  samples where the topic's primary channel is valid: header stamp =
  ``meta["t0_ns"] + t``, log time from ``<name>_log_time`` when kept. Reading
  the bag back with the same mapping gives the same frame (the round trip the
  tests check; NavSatFix and FluidPressure go through the inverse projection /
  pressure formula, so they agree to float round-off).
* :func:`export_run_ros2` writes one run of a ``replay eval`` output (or of a
  campaign's configurations, ``run_data.load_run``) for ``ros2 bag play``:
  ``/replay/<filter>/odom`` and ``/replay/reference/odom`` (nav_msgs/Odometry,
  frame ``enu``, child ``base_link``; position, heading as a yaw quaternion when
  the task estimates one; the pose covariance of position and heading from the estimate's
  full covariance (:func:`pose_covariance`); a
  north-east-down task converted to east-north-up, ``run_data.enu_axes``). A name
  that is not a valid ROS 2 topic token (``igwo-stcpf``, ``recorded:gps``) is written
  with its other characters as ``_`` (:func:`ros_name`).

Both bags are compressed as ``ros2 bag record -s mcap`` compresses them: zstd MCAP
chunks (``BagOut(compression="zstd")``), readable by rosbags, ``ros2 bag`` and any
MCAP reader; the test1 odometry export is 52 MB uncompressed and about 5 MB so.

No Foxglove JSON/protobuf channel ever goes into these bags. The writer,
:class:`~replay.adapters.bags.writer.BagOut`, is the ``bags`` adapter's inverse.

Both write the bag inside a hidden temporary directory beside the target and swap it
in when complete (``replay.outputs.export_safety.export_set``); the bag's
``metadata.yaml`` carries ``custom_data: {replay.output: ...}``, the mark that lets a
later export replace it. An existing directory without that mark is never replaced.
"""

from __future__ import annotations

import re

import numpy as np

from replay.adapters import rosmsg
from replay.adapters.bags.writer import BagOut
from replay.adapters.geodesy import enu_to_geodetic
from replay.outputs.export_safety import check_target, run_inputs
from replay.outputs.run_data import enu_axes, enu_yaw, load_run, ned, time_ns, to_enu, track_index
from replay.outputs.export_safety import MARK_KEY, export_set
from replay.util import covcols
from replay.util.errors import ReplayError


def _get(group, key, n, width):
    ch = group.get(key)
    if ch is None:
        return np.zeros((n, width)), np.zeros(n, bool)
    return ch.values.reshape(n, -1), ch.valid


def _cov(f, i, names, size):
    """The row-major ``size`` x ``size`` covariance of sample i whose diagonal blocks are the recorded
    ``<field>_var`` fields ``names`` (rosmsg: 3 entries each, raw), zeros where absent."""
    c = np.zeros(size * size)
    for b, name in enumerate(names):
        vals, ok = f.get(name, (None, None))
        if vals is not None and ok[i]:
            c[[(3 * b + j) * (size + 1) for j in range(3)]] = vals[i][:3]
    return c


def _message(out: BagOut, kind, typ, ns, i, f, fid, params, geo):
    """Build one message of ``kind`` from field arrays ``f`` at sample i."""
    T = out.T
    hdr = out.header(ns, fid.get("main", ""))
    if kind == "imu":
        att_ok = f["attitude"][1][i]
        q = rosmsg.rpy_to_quat(f["attitude"][0][i : i + 1])[0] if att_ok else np.array([0, 0, 0, 1.0])
        ocov = _cov(f, i, ("attitude_var",), 3)
        if not att_ok:
            ocov[0] = -1.0
        return T[typ](
            header=hdr,
            orientation=out.quat(q),
            orientation_covariance=ocov,
            angular_velocity=out.vec(f["gyro"][0][i]),
            angular_velocity_covariance=_cov(f, i, ("gyro_var",), 3),
            linear_acceleration=out.vec(f["accel"][0][i]),
            linear_acceleration_covariance=_cov(f, i, ("accel_var",), 3),
        )
    if kind == "odometry":
        q = rosmsg.rpy_to_quat(f["attitude"][0][i : i + 1])[0]
        msg = out.odometry(
            ns,
            fid.get("main", ""),
            fid.get("velocity", ""),
            f["position"][0][i],
            q,
            f["velocity"][0][i],
            f["rate"][0][i],
            _cov(f, i, ("position_var", "attitude_var"), 6),
        )
        msg.twist.covariance = _cov(f, i, ("velocity_var", "rate_var"), 6)
        return msg
    if kind == "pose":
        q = rosmsg.rpy_to_quat(f["attitude"][0][i : i + 1])[0]
        pose = out.pose(f["position"][0][i], q)
        if typ.endswith("PoseWithCovarianceStamped"):
            pose = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=pose, covariance=_cov(f, i, ("position_var", "attitude_var"), 6)
            )
        return T[typ](header=hdr, pose=pose)
    if kind == "twist":
        tw = out.twist(f["velocity"][0][i], f["rate"][0][i])
        if typ.endswith("TwistWithCovarianceStamped"):
            tw = T["geometry_msgs/msg/TwistWithCovariance"](
                twist=tw, covariance=_cov(f, i, ("velocity_var", "rate_var"), 6)
            )
        return T[typ](header=hdr, twist=tw)
    if kind == "pressure":
        rho = float(params.get("water_density", rosmsg.WATER_DENSITY))
        p_atm = float(params.get("atmospheric_pressure", rosmsg.ATMOSPHERIC_PRESSURE))
        g = float(params.get("gravity", rosmsg.GRAVITY))
        p = p_atm + rho * g * float(f["depth"][0][i][0])
        return T[typ](header=hdr, fluid_pressure=p, variance=0.0)
    if kind == "navsatfix":
        ok = f["position"][1][i]
        if ok:
            lat, lon, alt = (a[0] for a in geo(f["position"][0][i : i + 1]))
        else:
            lat = lon = alt = float("nan")
        status = int(f["status"][0][i][0]) if f["status"][1][i] else (0 if ok else -1)
        sig = f["sigma"][0][i]
        cov = np.zeros(9)
        cov[[0, 4, 8]] = np.where(np.isfinite(sig), sig**2, 0.0)
        if "position_var" in f and f["position_var"][1][i]:  # the recorded diagonal, raw
            cov = _cov(f, i, ("position_var",), 3)
        return T[typ](
            header=hdr,
            status=T["sensor_msgs/msg/NavSatStatus"](status=status, service=1),
            latitude=float(lat),
            longitude=float(lon),
            altitude=float(alt),
            position_covariance=cov,
            position_covariance_type=2,
        )
    raise ReplayError(f"cannot write message kind {kind}")


def write_frame_bag(frame, path) -> int:
    """Write the mapped topics of a ``bags`` frame back as a ROS 2 bag; returns messages written."""

    mapping = frame.meta.get("mapping")
    if not mapping or "t0_ns" not in frame.meta:
        raise ReplayError("write_frame_bag: the frame was not read by the bags adapter (no mapping / t0_ns)")
    t0 = int(frame.meta["t0_ns"])
    n = len(frame.t)
    ns = t0 + np.round(frame.t * 1e9).astype(np.int64)
    params = mapping.get("params") or {}
    geo = (lambda enu: enu_to_geodetic(enu, frame.meta)) if frame.meta.get("crs") else None
    other = "header_time" if mapping.get("time") == "log" else "log_time"
    with export_set(path, "ros2", what="bag").staged(nested=True) as tmp:
        return _write_frame(
            BagOut(tmp, {MARK_KEY: "frame bag"}, compression="zstd"), frame, mapping, n, ns, t0, params, geo, other
        )


def _write_frame(out, frame, mapping, n, ns, t0, params, geo, other) -> int:
    try:
        done = set()
        for e in mapping["entries"]:
            if e["topic"] in done:
                continue
            done.add(e["topic"])
            group = frame.reference if e["reference"] else frame.channels
            typ = e.get("type") or frame.meta["topics"][e["topic"]]["type"]
            kind = rosmsg.kind_of(typ)
            primary = rosmsg.PRIMARY[kind]
            name = e["name"]
            f, fid = {}, {}
            for key in group:
                if key == name or (key.startswith(name + "_") and key[len(name) + 1 :] != other):
                    fname = primary if key == name else key[len(name) + 1 :]
                    f[fname] = (group[key].values.reshape(n, -1), group[key].valid)
                    fid[fname] = group[key].frame
            for fname in ("gyro", "accel", "attitude", "position", "velocity", "rate", "depth", "status", "sigma"):
                f.setdefault(fname, (np.full((n, 3), np.nan), np.zeros(n, bool)))
            fid["main"] = fid.get(primary, "")
            t_other = group.get(f"{name}_{other}")
            present = t_other.valid if t_other is not None else f[primary][1]
            conn = out.connection(e["topic"], typ)
            for i in np.flatnonzero(present):
                stamp = int(ns[i])
                log = stamp
                if t_other is not None and mapping.get("time") != "log":
                    log = t0 + int(round(t_other.values[i] * 1e9))
                elif t_other is not None:  # time = log: the frame axis is the log time
                    stamp = t0 + int(round(t_other.values[i] * 1e9))
                    log = int(ns[i])
                out.write(conn, log, _message(out, kind, typ, stamp, i, f, fid, params, geo))
    finally:
        out.close()
    return out.count


def ros_name(name: str) -> str:
    """``name`` as a ROS 2 topic token: letters, digits and single underscores, not starting with a digit."""
    token = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", str(name))).strip("_") or "track"
    return f"f_{token}" if token[0].isdigit() else token


def export_run_ros2(run_dir, path, data_dir=None, run: int = 0, select=None, progress=None) -> int:
    """nav_msgs/Odometry per filter and for the reference (one run) -> ROS 2 bag (MCAP storage).

    Refused before anything is read or written: a target that is an input of the run
    (or inside one), or an existing directory that is not a bag this tool wrote.
    """

    inputs = run_inputs(run_dir, data_dir)
    check_target(path, inputs, "ros2")
    loaded = load_run(run_dir, data_dir, run=run, select=select)
    check_target(path, inputs + [loaded["frame"].meta.get("path")], "ros2")
    return write_run_ros2(loaded, path, progress=progress)


def write_run_ros2(run: dict, path, progress=None) -> int:
    """The odometry bag of a loaded run (``run_data.load_run``), staged and swapped in at ``path``;
    ``progress``: a :class:`replay.util.progress.Progress` told of the messages written."""
    with export_set(path, "ros2").staged(nested=True) as tmp:
        return _write_run(BagOut(tmp, {MARK_KEY: "replay export"}, compression="zstd"), run, progress)


def pose_covariance(P, pidx, hidx, axes, is_ned: bool) -> np.ndarray:
    """(n, 36) row-major 6 x 6 pose covariances (x, y, z, rotation about x, y, z; ENU) of the
    state covariances ``P`` (n, nx, nx): ``S P S^T`` with ``S`` taking the position components
    ``pidx`` to their ENU slots (``axes``, signs included) and the heading ``hidx`` to the
    rotation about z (its sign flipped for a clockwise-from-north heading). The rotations
    about x and y are not estimated: their rows are 0, as before (variances only)."""
    P = covcols.as_matrices(P)
    S = np.zeros((6, P.shape[-1]))
    for i, (slot, sign) in zip(pidx, axes):
        S[slot, i] = sign
    if hidx is not None:
        S[5, hidx] = -1.0 if is_ned else 1.0
    return (S @ P @ S.T).reshape(len(P), 36)


PROGRESS_EVERY = 4096  # messages between two progress updates


def _write_run(out, run, progress=None) -> int:

    frame, problem = run["frame"], run["problem"]
    axes, is_ned = enu_axes(problem), ned(problem)
    try:
        tracks = [("reference", time_ns(frame, frame.t), problem.truth_position, None, None, problem.truth_valid)]
        for name, est in run["estimates"].items():
            pidx, hidx = track_index(name, problem)
            tracks.append(
                (
                    name,
                    time_ns(frame, est["t"]),
                    est["x"][:, pidx],
                    enu_yaw(est["x"][:, hidx], is_ned) if hidx is not None else None,
                    pose_covariance(est["P"], pidx, hidx, axes, is_ned),
                    None,
                )
            )
        topics = {}
        for name, *_ in tracks:
            topic = f"/replay/{ros_name(name)}/odom"
            if topic in topics:
                raise ReplayError(f"--ros2-bag: tracks {topics[topic]!r} and {name!r} would both be {topic}")
            topics[topic] = name
        rows = []
        for name, ns, pos, yaw, var, ok in tracks:
            pos = to_enu(pos, axes)
            ok = np.isfinite(pos).all(axis=1) if ok is None else ok & np.isfinite(pos).all(axis=1)
            rows.append((ns, pos, yaw, var, np.flatnonzero(ok)))
        total, told = sum(len(r[-1]) for r in rows), 0
        if progress is not None:
            progress.start(total)
        for topic, (ns, pos, yaw, var, idx) in zip(topics, rows):
            conn = out.connection(topic, "nav_msgs/msg/Odometry")
            for i in idx:
                y = float(yaw[i]) if yaw is not None and np.isfinite(yaw[i]) else 0.0
                cov = np.zeros(36) if var is None else var[i]
                out.write(
                    conn,
                    int(ns[i]),
                    out.odometry(
                        int(ns[i]),
                        "enu",
                        "base_link",
                        pos[i],
                        (0.0, 0.0, np.sin(y / 2), np.cos(y / 2)),
                        (0, 0, 0),
                        (0, 0, 0),
                        cov,
                    ),
                )
                if progress is not None and out.count - told >= PROGRESS_EVERY and out.count < total:
                    progress.update(out.count - told)
                    told = out.count
    finally:
        out.close()
    if progress is not None:  # the total only once the bag is closed
        progress.update(out.count - told)
    return out.count
