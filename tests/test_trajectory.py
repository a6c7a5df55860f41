"""replay.trajectory: readers and their refusals, association, alignment, pose errors, bags and tf.

Agreement with evo itself is in tests/test_trajectory_evo.py.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from replay.scoring import align
from replay.trajectory import Trajectory, associate, load, make, pose_error, quat, row_metrics, score
from replay.trajectory.files import write_tum
from replay.util.errors import DataError, ReplayError


def helix(n=200, dt=0.1, t0=100.0, seed=0):
    rng = np.random.default_rng(seed)
    t = t0 + np.arange(n) * dt
    s = np.arange(n) * dt
    p = np.column_stack([10 * np.cos(s / 4), 10 * np.sin(s / 4), s / 5]) + rng.normal(0, 0.01, (n, 3))
    q = Rotation.from_euler("xyz", np.column_stack([0.1 * np.sin(s), 0.05 * np.cos(s), s / 4])).as_quat()
    return make(t, p, q, source="helix")


def moved(tr, R, t, c=1.0, **kw):
    return Trajectory(tr.t, c * tr.p @ R.T + t, quat.multiply(quat.from_matrix(R), tr.q), **kw)


# ---------------------------------------------------------------- readers


def test_tum_round_trip(tmp_path):
    tr = helix()
    write_tum(tmp_path / "a.txt", tr)
    back = load(str(tmp_path / "a.txt"))
    np.testing.assert_array_equal(back.t, tr.t)
    np.testing.assert_allclose(back.p, tr.p, rtol=0, atol=0)
    np.testing.assert_allclose(back.q, tr.q, atol=1e-15)
    assert back.name == "a.txt"


@pytest.mark.parametrize("body,what", [
    ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n3 0 0 0 0 0 0.5 1\n",
     "row 3: quaternion (x, y, z, w) = [0.0, 0.0, 0.5, 1.0] has norm 1.11803"),
    ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n", "row 3: duplicate stamp 2.000000000 s"),
    ("1 0 0 0 0 0 0 1\n3 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n", "row 3: time goes backwards: stamp 2.000000000 s"),
    ("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n", "2 poses: a trajectory needs at least 3"),
    ("# t x y z qx qy qz qw\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n", "row 3: 7 columns, expected 8"),
    ("1 0 0 0 0 0 0 1\n2 0 0 x 0 0 0 1\n3 0 0 0 0 0 0 1\n", "row 2: column 4: 'x' is not a number"),
    ("1 0 0 0 0 0 0 1\n2 0 0 nan 0 0 0 1\n3 0 0 0 0 0 0 1\n", "row 2: position [0.0, 0.0, nan] is not finite"),
    ("\n\n", "empty file"),
])
def test_tum_bad_input_one_line(tmp_path, body, what):
    path = tmp_path / "bad.tum"
    path.write_text(body)
    with pytest.raises(DataError) as e:
        load(str(path))
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(str(path)) and what in msg, msg


def test_quaternions_within_tolerance_are_normalised(tmp_path):
    path = tmp_path / "a.tum"
    path.write_text("1 0 0 0 0 0 0 1.0005\n2 1 0 0 0 0 0 0.9996\n3 2 0 0 0 0 0 1\n")
    tr = load(str(path))
    np.testing.assert_allclose(np.linalg.norm(tr.q, axis=1), 1.0, atol=1e-15)


def kitti_rows(tr):
    return np.concatenate([quat.to_matrix(tr.q), tr.p[:, :, None]], axis=2).reshape(-1, 12)


def test_kitti_needs_times_and_reads_them(tmp_path):
    tr = helix(50)
    np.savetxt(tmp_path / "poses.txt", kitti_rows(tr), fmt="%.17g")
    with pytest.raises(DataError, match="KITTI poses carry no stamps: give a times file"):
        load(str(tmp_path / "poses.txt"))
    np.savetxt(tmp_path / "stamps.txt", tr.t, fmt="%.17g")
    back = load(str(tmp_path / "poses.txt"), kitti_times=tmp_path / "stamps.txt")
    np.testing.assert_allclose(back.p, tr.p, atol=1e-12)
    assert np.all(quat.angle(quat.multiply(quat.conjugate(back.q), tr.q)) < 1e-7)
    np.savetxt(tmp_path / "times.txt", tr.t[:-1], fmt="%.17g")  # beside the poses, one stamp short
    with pytest.raises(DataError, match="49 stamps for the 50 poses"):
        load(str(tmp_path / "poses.txt"))


def test_kitti_refuses_a_matrix_that_is_no_rotation(tmp_path):
    rows = kitti_rows(helix(5))
    rows[3, 0] *= 1.1
    np.savetxt(tmp_path / "p.kitti", rows)
    np.savetxt(tmp_path / "times.txt", np.arange(5.0))
    with pytest.raises(DataError, match=r"row 4: the 3x3 block is not a rotation"):
        load(str(tmp_path / "p.kitti"))


def test_plain_csv_with_declared_columns(tmp_path):
    tr = helix(20)
    yaw = Rotation.from_quat(tr.q).as_euler("ZYX")[:, 0]
    lines = ["stamp_ns;east;north;up;heading"] + [f"{int(round(t * 1e9))};{p[0]:.17g};{p[1]:.17g};{p[2]:.17g};{y:.17g}"
                                                   for t, p, y in zip(tr.t, tr.p, yaw)]
    path = tmp_path / "nav.csv"
    path.write_text("\n".join(lines) + "\n")
    back = load(str(path), columns="t=stamp_ns,x=east,y=north,z=up,yaw=heading", time_unit="ns")
    np.testing.assert_allclose(back.t, tr.t, atol=1e-9)
    np.testing.assert_allclose(back.p, tr.p)
    np.testing.assert_allclose(Rotation.from_quat(back.q).as_euler("ZYX")[:, 0], yaw, atol=1e-12)
    with pytest.raises(DataError, match="no column 'x_m' in the header"):
        load(str(path), columns="t=stamp_ns,x=x_m,y=north")
    with pytest.raises(DataError, match="a plain CSV needs its columns declared"):
        load(str(path), fmt="csv")


def test_format_detection_refuses_unknown_layout(tmp_path):
    path = tmp_path / "x.txt"
    path.write_text("1 2 3\n4 5 6\n7 8 9\n")
    with pytest.raises(DataError, match="cannot tell the format .3 columns"):
        load(str(path))
    with pytest.raises(DataError, match="no such file"):
        load(str(tmp_path / "missing.tum"))


@pytest.mark.parametrize("header,fmt,columns,unit", [
    ("#timestamp,x,y,z,qx,qy,qz,qw", "csv", "01234567", None),
    ("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []", "euroc",
     None, None),
    ("#timestamp [ns],p_x,p_y,p_z,q_w,q_x,q_y,q_z", "euroc", None, None),
    ("# timestamp tx ty tz qx qy qz qw", "tum", None, None),
    ("# timestamp(s) tx ty tz qx qy qz qw", "tum", None, None),
    ("# t x y z qw qx qy qz", "csv", "01235674", None),
    ("time_ms;pose.position.x;pose.position.y;pose.position.z;pose.orientation.x;pose.orientation.y;"
     "pose.orientation.z;pose.orientation.w", "csv", "01234567", "ms"),
    ("qw,qx,qy,qz,x,y,z,stamp", "csv", "74561230", None),
    ("t_s,x_m,y_m,z_m,qx,qy,qz,qw", "csv", "01234567", "s"),
    ("%time,field.header.stamp,field.pose.position.x,field.pose.position.y,field.pose.position.z,"
     "field.pose.orientation.x,field.pose.orientation.y,field.pose.orientation.z,field.pose.orientation.w", "csv",
     "12345678", None),
])
def test_layout_is_read_from_the_header_names(header, fmt, columns, unit):
    from replay.trajectory.layout import FIELDS, decide

    sep = "," if "," in header else ";" if ";" in header else " "
    got = decide("f", header + "\n" + sep.join(["1"] * len(header.lstrip("#").split(sep.strip() or None))) + "\n", None)
    want = {f: int(c) for f, c in zip(FIELDS, columns)} if columns else None
    assert got == (fmt, want, unit)


# ---------------------------------------------------------------- association


def test_association_nearest_within_max_diff_like_evo():
    ref = make([0.0, 1.0, 2.0, 3.0, 4.0], np.zeros((5, 3)), source="ref")
    est = make([0.004, 1.5, 2.009, 2.9951, 9.0], np.zeros((5, 3)), source="est")
    i_ref, i_est = associate(ref, est, t_max_diff=0.01)
    assert i_ref.tolist() == [0, 2, 3] and i_est.tolist() == [0, 2, 3]
    # the offset is added to the estimate's stamps
    est2 = make([10.0, 11.0, 12.005, 13.0], np.zeros((4, 3)), source="est2")
    i_ref, i_est = associate(ref, est2, t_offset=-10.0)
    assert i_ref.tolist() == [0, 1, 2, 3] and i_est.tolist() == [0, 1, 2, 3]
    # a tie goes to the earlier pose
    tie = make([0.5, 1.5, 2.5], np.zeros((3, 3)), source="tie")
    i_ref, i_est = associate(ref, tie, t_max_diff=0.5)
    assert i_ref.tolist() == [0, 1, 2]


def test_association_refusals_name_both_sources():
    ref = make(np.arange(10.0), np.zeros((10, 3)), source="gt.tum")
    far = make(np.arange(10.0) + 100, np.zeros((10, 3)), source="slam.tum")
    with pytest.raises(ReplayError, match=r"slam.tum against gt.tum: the time spans do not overlap"):
        associate(ref, far)
    few = make([0.0, 1.0, 5.5, 6.5], np.zeros((4, 3)), source="slam.tum")
    with pytest.raises(ReplayError, match=r"slam.tum against gt.tum: 2 poses matched within t_max_diff 0.01 s"):
        associate(ref, few)


# ---------------------------------------------------------------- alignment


def test_alignment_recovers_transforms_and_n_to_align():
    ref = helix()
    R = Rotation.from_euler("zyx", [1.0, 0.2, -0.1]).as_matrix()
    est = moved(ref, R.T, -R.T @ [3.0, 1.0, 2.0], 1 / 1.5)  # ref = 1.5 R est + [3, 1, 2]
    for method in ("se3", "sim3"):
        s = score(ref, est, align=method, relations=["trans", "angle_deg"])
        if method == "sim3":
            assert s.stats()["max"] < 1e-9 and s.stats("ape", "angle_deg")["max"] < 1e-6
            assert s.transform[2] == pytest.approx(1.5)
        else:
            assert s.stats()["rmse"] > 0.1
    # n_to_align: a trajectory that is exact for its first 50 poses and drifts afterwards
    bent = Trajectory(est.t, est.p + np.where(np.arange(len(est))[:, None] >= 50, [0.0, 0.0, 1.0], 0.0), est.q)
    s = score(ref, bent, align="sim3", n_to_align=50)
    e = s.ape["trans"]
    assert e[:50].max() < 1e-9 and e[50:].min() == pytest.approx(1.5, rel=1e-9)


def test_yaw_alignment_is_the_least_squares_optimum():
    ref = helix(300, seed=1)
    rng = np.random.default_rng(2)
    Rz = Rotation.from_euler("z", 0.7).as_matrix()
    noisy = Trajectory(ref.t, ref.p @ Rz.T + [2.0, -1.0, 0.5] + rng.normal(0, 0.2, ref.p.shape), ref.q)
    R, t, c = align.align(noisy.p, ref.p, "yaw")

    def sse(x):
        Ry = Rotation.from_euler("z", x[0]).as_matrix()
        return np.sum((noisy.p @ Ry.T + x[1:] - ref.p) ** 2)

    yaw = math.atan2(R[1, 0], R[0, 0])
    best = minimize(sse, [yaw + 0.05, *(t + 0.1)], method="BFGS", options={"gtol": 1e-10})
    assert sse([yaw, *t]) <= best.fun * (1 + 1e-12)
    assert abs(yaw - best.x[0]) < 1e-6 and c == 1.0
    np.testing.assert_allclose(R[2], [0, 0, 1])
    np.testing.assert_allclose(R[:, 2], [0, 0, 1])


def test_origin_alignment_and_refusals():
    ref = helix()
    R = Rotation.from_euler("z", 2.0).as_matrix()
    est = moved(ref, R, [5.0, 5.0, 0.0])
    s = score(ref, est, align_origin=True, relations=["full"])
    assert s.stats("ape", "full")["max"] < 1e-9
    with pytest.raises(ReplayError, match="origin alignment and se3 alignment exclude each other"):
        score(ref, est, align="se3", align_origin=True)
    line = make(np.arange(10.0), np.column_stack([np.arange(10.0), np.zeros(10), np.zeros(10)]), source="line")
    with pytest.raises(ReplayError, match="se3 alignment is undetermined"):
        score(line, line, align="se3")


# ---------------------------------------------------------------- pose errors


def test_pose_relations_known_values():
    theta = 0.3
    q_ref = np.array([[0.0, 0.0, 0.0, 1.0]])
    q_est = Rotation.from_rotvec([[0.0, 0.0, theta]]).as_quat()
    kw = dict(p_ref=np.zeros((1, 3)), q_ref=q_ref, p_est=np.array([[3.0, 4.0, 0.0]]), q_est=q_est)
    R = Rotation.from_rotvec([0.0, 0.0, theta]).as_matrix()
    assert pose_error.ape(**kw, relation="trans")[0] == pytest.approx(5.0)
    assert pose_error.ape(**kw, relation="angle_rad")[0] == pytest.approx(theta)
    assert pose_error.ape(**kw, relation="angle_deg")[0] == pytest.approx(math.degrees(theta))
    assert pose_error.ape(**kw, relation="rot")[0] == pytest.approx(np.linalg.norm(R - np.eye(3)))
    E = np.eye(4)
    E[:3, :3], E[:3, 3] = R.T, -R.T @ [3.0, 4.0, 0.0]  # P^-1 Q with Q = I
    assert pose_error.ape(**kw, relation="full")[0] == pytest.approx(np.linalg.norm(E - np.eye(4)))


def test_statistics_as_evo_defines_them():
    s = pose_error.statistics([1.0, 2.0, 3.0, 6.0])
    assert s == pytest.approx({"rmse": math.sqrt(12.5), "mean": 3.0, "median": 2.5, "std": math.sqrt(3.5),
                               "min": 1.0, "max": 6.0, "sse": 50.0})


def test_rpe_pairs_frames_metres_seconds():
    p = np.column_stack([np.cumsum([0, 1, 1, 1, 1, 1, 1, 1.0]), np.zeros(8), np.zeros(8)])
    t = np.arange(8) * 0.5
    kw = dict(p=p, q=None, t=t)
    i, j = pose_error.pairs(**kw, delta=3, unit="f")
    assert list(zip(i, j)) == [(0, 3), (3, 6)]
    i, j = pose_error.pairs(**kw, delta=3, unit="f", all_pairs=True)
    assert list(zip(i, j)) == [(k, k + 3) for k in range(5)]
    i, j = pose_error.pairs(**kw, delta=2.5, unit="m")
    assert list(zip(i, j)) == [(0, 3), (3, 6)]
    i, j = pose_error.pairs(**kw, delta=2.1, unit="m", all_pairs=True, rel_tol=0.1)
    assert list(zip(i, j)) == [(k, k + 2) for k in range(6)]
    i, j = pose_error.pairs(**kw, delta=1.0, unit="s")
    assert list(zip(i, j)) == [(0, 2), (2, 4), (4, 6)]
    with pytest.raises(ReplayError, match="gives no pose pair"):
        pose_error.pairs(**kw, delta=100, unit="m")
    with pytest.raises(ReplayError, match="needs orientations"):
        pose_error.pairs(**kw, delta=10, unit="d")


def test_rpe_of_a_constant_offset_is_zero_and_drift_is_reported():
    ref = helix()
    est = moved(ref, Rotation.from_euler("z", 0.4).as_matrix(), [1.0, 2.0, 3.0])
    s = score(ref, est, relations=["trans", "angle_deg", "full"], delta=1, delta_unit="m")
    assert max(s.stats("rpe", r)["max"] for r in ("trans", "angle_deg", "full")) < 1e-9
    row = row_metrics(s)
    assert row["rpe_trans_rmse"] < 1e-9 and row["rpe_drift_pct"] < 1e-7
    assert row["matched"] == len(ref) and row["scale"] == 1.0 and row["ate"] == pytest.approx(row["pos_rmse"])


def test_nees_and_lost_track_in_row_metrics():
    ref = helix(100)
    rng = np.random.default_rng(5)
    sigma = 0.5
    est = make(ref.t, ref.p + rng.normal(0, sigma, ref.p.shape), ref.q,
               np.tile(np.eye(6) * sigma**2, (100, 1, 1)), source="ekf")
    row = row_metrics(score(ref, est))
    assert 2.0 < row["nees"] < 4.0 and row["anees_flag"] == "consistent"
    far = make(ref.t, ref.p + np.where(np.arange(100)[:, None] > 80, 30.0, 0.0), ref.q, source="far")
    assert row_metrics(score(ref, far), lost_threshold=20, lost_steps=10)["lost"] == 1
    assert row_metrics(score(ref, far), lost_threshold=20, lost_steps=30)["lost"] == 0


# ---------------------------------------------------------------- bags


@pytest.fixture(scope="module")
def small_bag(tmp_path_factory):
    """A ROS 2 bag (MCAP) with Odometry (covariance), PoseStamped, Path, tf chain and a static edge."""
    from replay.adapters.bags import BagOut

    path = tmp_path_factory.mktemp("bag") / "run"
    tr = helix(60)
    out = BagOut(path)
    T = out.T
    odom = out.connection("/odometry/filtered", "nav_msgs/msg/Odometry")
    pose = out.connection("/slam/pose", "geometry_msgs/msg/PoseStamped")
    path_c = out.connection("/slam/path", "nav_msgs/msg/Path")
    tf = out.connection("/tf", "tf2_msgs/msg/TFMessage")
    tf_static = out.connection("/tf_static", "tf2_msgs/msg/TFMessage")
    ns = (tr.t * 1e9).round().astype(np.int64)
    cov = np.diag([0.04, 0.04, 0.09, 0.01, 0.01, 0.01]).ravel()
    off = np.array([100.0, 0.0, 0.0])
    stat = T["geometry_msgs/msg/TransformStamped"](
        header=out.header(0, "base_link"), child_frame_id="camera",
        transform=T["geometry_msgs/msg/Transform"](translation=out.vec([0.5, 0, 0]), rotation=out.quat([0, 0, 0, 1])))
    out.write(tf_static, ns[0], T["tf2_msgs/msg/TFMessage"](transforms=[stat]))
    stamped = []
    for k in range(len(tr)):
        h = out.header(ns[k], "odom")
        pwc = T["geometry_msgs/msg/PoseWithCovariance"](pose=out.pose(tr.p[k], tr.q[k]), covariance=cov)
        twc = T["geometry_msgs/msg/TwistWithCovariance"](twist=out.twist([0, 0, 0], [0, 0, 0]),
                                                          covariance=np.zeros(36))
        out.write(odom, ns[k], T["nav_msgs/msg/Odometry"](header=h, child_frame_id="base_link", pose=pwc, twist=twc))
        ps = T["geometry_msgs/msg/PoseStamped"](header=out.header(ns[k], "map"), pose=out.pose(tr.p[k] + off, tr.q[k]))
        out.write(pose, ns[k], ps)
        stamped.append(ps)
        edges = [("odom", "base_link", tr.p[k], tr.q[k])]
        if k % 2 == 0:  # map -> odom at half the rate: a pure shift of 100 m in x
            edges.append(("map", "odom", off, [0.0, 0.0, 0.0, 1.0]))
        msg = T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
            header=out.header(ns[k], a), child_frame_id=b,
            transform=T["geometry_msgs/msg/Transform"](translation=out.vec(p), rotation=out.quat(q)))
            for a, b, p, q in edges])
        out.write(tf, ns[k], msg)
        if k in (30, 59):
            out.write(path_c, ns[k], T["nav_msgs/msg/Path"](header=out.header(ns[k], "map"), poses=list(stamped)))
    out.close()
    return path, tr


def test_bag_topics_and_tf(small_bag):
    from replay.trajectory.io import load_all

    path, tr = small_bag
    odom, slam, last_path, tf_chain, tf_static = load_all(
        [f"{path}:/odometry/filtered", f"{path}:slam/pose", f"{path}:/slam/path", f"{path}:tf:map->base_link",
         f"{path}:tf:odom->camera"])
    np.testing.assert_allclose(odom.p, tr.p)
    assert odom.cov.shape == (60, 6, 6) and odom.cov[0, 2, 2] == pytest.approx(0.09)
    np.testing.assert_allclose(slam.p, tr.p + [100.0, 0, 0])
    assert len(last_path) == 60  # the last Path message holds every pose
    np.testing.assert_allclose(last_path.t, tr.t, atol=1e-9)
    # map -> base_link: stamps of the faster odom -> base_link edge, inside the span of map -> odom
    assert len(tf_chain) == 59
    np.testing.assert_allclose(tf_chain.p, tr.p[:59] + [100.0, 0, 0], atol=1e-9)
    assert score(slam, tf_chain, relations=["full"]).stats("ape", "full")["max"] < 1e-9
    cam = tr.p + quat.rotate(tr.q, [0.5, 0.0, 0.0])  # odom -> base_link -> camera (static)
    np.testing.assert_allclose(tf_static.p, cam, atol=1e-9)


def test_bag_refusals_one_line(small_bag):
    path, _ = small_bag
    with pytest.raises(DataError, match=r"no topic '/gps' \(trajectory topics: /odometry/filtered \(Odometry\)"):
        load(f"{path}:/gps")
    with pytest.raises(DataError, match="frame 'world' is not in the tf tree"):
        load(f"{path}:tf:world->base_link")
    with pytest.raises(DataError, match="only static transforms join these frames"):
        load(f"{path}:tf:base_link->camera")
    with pytest.raises(DataError, match="a tf topic: name the frames"):
        load(f"{path}:/tf")
    with pytest.raises(DataError, match="a recording needs a topic"):
        load(str(path))
