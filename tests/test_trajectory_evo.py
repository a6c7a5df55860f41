"""Agreement with evo (the oracle, GPL, a test-only dependency; the library never imports it).

For every alignment mode and pose relation, our APE and RPE statistics equal evo's
(``evo.main_ape.ape``, ``evo.main_rpe.rpe`` after ``evo.core.sync.associate_trajectories``)
to 1e-6 relative (values at rounding level, such as the 0 of origin alignment, to 1e-12 m):

* on ``ROS_example.bag`` (evo's own test data): groundtruth vs ORB-SLAM and S-PTAM,
  the bag read by rosbags here for evo and by ``replay.trajectory`` for us (slow: 26k messages);
* on a TUM pair and a KITTI pair generated in ``tmp_path``, read by evo's own readers'
  rules (TUM: ``t x y z qx qy qz qw``; KITTI: 3x4 rows, no stamps: matched by index).

evo has no yaw-only (4-DoF) alignment: there the estimate is moved by our yaw transform and
evo scores it unaligned; the yaw fit itself is checked for optimality in test_trajectory.py.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from replay.trajectory import load, pose_error, score

evo = pytest.importorskip("evo", reason="evo (the test oracle) is not installed: pip install -e '.[test]'")
from evo.core import metrics as evo_metrics  # noqa: E402
from evo.core import lie_algebra as lie  # noqa: E402
from evo.core import sync  # noqa: E402
from evo.core.trajectory import PosePath3D, PoseTrajectory3D  # noqa: E402
from evo.main_ape import ape as evo_ape  # noqa: E402
from evo.main_rpe import rpe as evo_rpe  # noqa: E402

REL = {"trans": "translation_part", "rot": "rotation_part", "full": "full_transformation",
       "angle_deg": "rotation_angle_deg", "angle_rad": "rotation_angle_rad", "point_distance": "point_distance",
       "point_distance_error_ratio": "point_distance_error_ratio"}
UNIT = {"f": "frames", "m": "meters", "d": "degrees", "r": "radians"}
ALIGNS = [("none", False), ("se3", False), ("sim3", False), ("scale", False), ("none", True), ("scale", True),
          ("yaw", False)]
APE_RELATIONS = ["trans", "rot", "full", "angle_deg", "angle_rad", "point_distance"]
RPE_RELATIONS = APE_RELATIONS + ["point_distance_error_ratio"]


def evo_traj(tr, stamps=True):
    q_wxyz = np.roll(tr.q, 1, axis=1)
    if stamps:
        return PoseTrajectory3D(tr.p.copy(), q_wxyz, tr.t.copy())
    return PosePath3D(tr.p.copy(), q_wxyz)


def evo_stats(ref, est, *, align, origin, relation, n_to_align=-1, rpe=None, t_max_diff=0.01, t_offset=0.0,
              yaw_transform=None):
    """evo's statistics, with evo's pipeline (association, Umeyama, metric)."""
    ref, est = copy.deepcopy(ref), copy.deepcopy(est)
    if isinstance(ref, PoseTrajectory3D):
        ref, est = sync.associate_trajectories(ref, est, max_diff=t_max_diff, offset_2=t_offset)
    if yaw_transform is not None:
        R, t, _ = yaw_transform
        est.transform(lie.se3(R, t))
    kw = dict(align=align in ("se3", "sim3"), correct_scale=align in ("sim3", "scale"), n_to_align=n_to_align,
              align_origin=origin)
    rel = evo_metrics.PoseRelation[REL[relation]]
    if rpe is None:
        return evo_ape(ref, est, rel, **kw).stats
    delta, unit, all_pairs = rpe
    return evo_rpe(ref, est, rel, delta=delta, delta_unit=evo_metrics.Unit[UNIT[unit]], all_pairs=all_pairs,
                   **kw).stats


def assert_same(ours: dict, theirs: dict, what: str, scale: float = 1.0):
    for k in pose_error.STATISTICS:
        a, b = ours[k], float(theirs[k])
        assert np.isclose(a, b, rtol=1e-6, atol=1e-12 * max(scale, 1.0)), f"{what}: {k} ours {a!r} evo {b!r}"


def check(ref, est, ref_evo, est_evo, *, aligns, relations, case=None, n_to_align=None, t_max_diff=0.01,
          t_offset=0.0) -> int:
    """Compare ours with evo for each alignment in ``aligns`` and relation; APE when ``case`` is None,
    else RPE over ``case`` = (delta, unit, all_pairs). Returns the number of comparisons."""
    checked = 0
    for align, origin in aligns:
        kind = f"align={align}{'+origin' if origin else ''}"
        s = score(ref, est, align=align, align_origin=origin, n_to_align=n_to_align, t_max_diff=t_max_diff,
                  t_offset=t_offset, relations=relations,
                  **({} if case is None else dict(delta=case[0], delta_unit=case[1], all_pairs=case[2])))
        errs = s.ape if case is None else s.rpe
        for rel in relations:
            theirs = evo_stats(ref_evo, est_evo, align=align, origin=origin, relation=rel, rpe=case,
                               n_to_align=-1 if n_to_align is None else n_to_align, t_max_diff=t_max_diff,
                               t_offset=t_offset, yaw_transform=s.transform if align == "yaw" else None)
            assert_same(pose_error.statistics(errs[rel]), theirs,
                        f"{'APE' if case is None else f'RPE {case}'} {rel} {kind}")
            checked += 1
    return checked


def check_all(ref, est, ref_evo, est_evo, *, rpe_cases, **kw) -> int:
    """Every alignment x every relation, APE and the RPE of each case."""
    n = check(ref, est, ref_evo, est_evo, aligns=ALIGNS, relations=APE_RELATIONS, **kw)
    for case in rpe_cases:
        n += check(ref, est, ref_evo, est_evo, aligns=ALIGNS, relations=RPE_RELATIONS, case=case, **kw)
    return n


def smooth_trajectory(rng, n, dt=0.1, t0=1.7e9):
    """A wandering 3-D path with turning attitude (a drone-like flight)."""
    t = t0 + np.arange(n) * dt
    s = np.arange(n) * dt
    p = np.column_stack([20 * np.sin(s / 15), 12 * np.sin(s / 7) + s / 3, 3 * np.sin(s / 5)])
    p += np.cumsum(rng.normal(0, 0.02, (n, 3)), axis=0)
    rpy = np.column_stack([0.2 * np.sin(s / 3), 0.15 * np.cos(s / 4), s / 6]) + np.cumsum(
        rng.normal(0, 0.005, (n, 3)), axis=0)
    return t, p, Rotation.from_euler("xyz", rpy).as_quat()


def noisy_estimate(rng, t, p, q, *, R, offset, scale=1.0):
    n = len(t)
    pe = scale * (p + np.cumsum(rng.normal(0, 0.03, (n, 3)), axis=0)) @ R.T + offset
    qe = (Rotation.from_matrix(R) * Rotation.from_quat(q) * Rotation.from_rotvec(
        np.cumsum(rng.normal(0, 0.004, (n, 3)), axis=0))).as_quat()
    return pe, qe


@pytest.fixture(scope="module")
def tum_pair(tmp_path_factory):
    rng = np.random.default_rng(14)
    d = tmp_path_factory.mktemp("tum")
    t, p, q = smooth_trajectory(rng, 400)
    R = Rotation.from_euler("zyx", [0.8, 0.05, -0.03]).as_matrix()
    pe, qe = noisy_estimate(rng, t, p, q, R=R, offset=[5.0, -3.0, 1.0], scale=1.3)
    keep = np.sort(rng.choice(len(t), 260, replace=False))  # a sparser estimate with jittered stamps
    te = t[keep] + rng.uniform(-0.004, 0.004, len(keep))
    np.savetxt(d / "ref.tum", np.column_stack([t, p, q]), fmt="%.17g")
    np.savetxt(d / "est.tum", np.column_stack([te, pe[keep], qe[keep]]), fmt="%.17g")
    return d / "ref.tum", d / "est.tum"


def read_tum_for_evo(path):
    m = np.loadtxt(path)
    return PoseTrajectory3D(m[:, 1:4], np.roll(m[:, 4:8], 1, axis=1), m[:, 0])


def test_tum_agrees_with_evo_quick(tum_pair):
    """The quick subset (not slow): SE(3)/Sim(3), translation and angle, APE and RPE over 1 frame and 2 m."""
    ref, est = load(str(tum_pair[0])), load(str(tum_pair[1]))
    ref_evo, est_evo = read_tum_for_evo(tum_pair[0]), read_tum_for_evo(tum_pair[1])
    for align in ("se3", "sim3"):
        for case in (None, (1, "f", False), (2.0, "m", False)):
            s = score(ref, est, align=align, relations=["trans", "angle_deg"],
                      **({} if case is None else dict(delta=case[0], delta_unit=case[1])))
            for rel in ("trans", "angle_deg"):
                assert_same(pose_error.statistics((s.ape if case is None else s.rpe)[rel]),
                            evo_stats(ref_evo, est_evo, align=align, origin=False, relation=rel, rpe=case),
                            f"{case} {rel} {align}")


@pytest.mark.slow
def test_tum_agrees_with_evo_every_alignment_and_relation(tum_pair):
    ref, est = load(str(tum_pair[0])), load(str(tum_pair[1]))
    ref_evo, est_evo = read_tum_for_evo(tum_pair[0]), read_tum_for_evo(tum_pair[1])
    cases = [(1, "f", False), (5, "f", True), (2.0, "m", False), (2.0, "m", True), (10.0, "d", False),
             (0.2, "r", False)]
    assert check_all(ref, est, ref_evo, est_evo, rpe_cases=cases) == len(ALIGNS) * (6 + 7 * len(cases))


@pytest.mark.slow
def test_tum_agrees_with_evo_n_to_align_offset_and_angle_all_pairs(tum_pair):
    ref, est = load(str(tum_pair[0])), load(str(tum_pair[1]))
    ref_evo, est_evo = read_tum_for_evo(tum_pair[0]), read_tum_for_evo(tum_pair[1])
    for align in ("se3", "sim3"):
        s = score(ref, est, align=align, n_to_align=100, relations=["trans", "angle_deg"])
        for rel in ("trans", "angle_deg"):
            assert_same(s.stats("ape", rel), evo_stats(ref_evo, est_evo, align=align, origin=False, relation=rel,
                                                       n_to_align=100), f"APE {rel} {align} n_to_align=100")
    # a clock offset: the estimate's stamps shifted by 0.5 s, associated back with t_offset
    shifted = type(est)(est.t - 0.5, est.p, est.q, name="shifted")
    sh_evo = PoseTrajectory3D(est_evo.positions_xyz, est_evo.orientations_quat_wxyz, est_evo.timestamps - 0.5)
    s = score(ref, shifted, align="se3", t_offset=0.5, t_max_diff=0.02)
    assert_same(s.stats(), evo_stats(ref_evo, sh_evo, align="se3", origin=False, relation="trans", t_offset=0.5,
                                     t_max_diff=0.02), "APE with t_offset")
    s = score(ref, est, align="se3", relations=["trans", "angle_rad"], delta=15.0, delta_unit="d", all_pairs=True)
    for rel in ("trans", "angle_rad"):
        assert_same(pose_error.statistics(s.rpe[rel]),
                    evo_stats(ref_evo, est_evo, align="se3", origin=False, relation=rel, rpe=(15.0, "d", True)),
                    f"RPE all pairs 15 deg {rel}")


@pytest.mark.slow
def test_kitti_agrees_with_evo_every_alignment_and_relation(tmp_path):
    rng = np.random.default_rng(7)
    t, p, q = smooth_trajectory(rng, 250, dt=0.1, t0=0.0)
    R = Rotation.from_euler("z", -1.1).as_matrix()
    pe, qe = noisy_estimate(rng, t, p, q, R=R, offset=[1.0, 2.0, 0.0], scale=0.7)
    for name, pp, qq in (("gt.txt", p, q), ("est.txt", pe, qe)):
        M = np.concatenate([Rotation.from_quat(qq).as_matrix(), pp[:, :, None]], axis=2).reshape(-1, 12)
        np.savetxt(tmp_path / name, M, fmt="%.17g")
    np.savetxt(tmp_path / "times.txt", t, fmt="%.17g")
    ref, est = load(str(tmp_path / "gt.txt")), load(str(tmp_path / "est.txt"))

    def kitti_for_evo(path):  # evo's read_kitti_poses_file: a path of 4x4 poses, no stamps
        m = np.loadtxt(path)
        return PosePath3D(poses_se3=[np.vstack([r.reshape(3, 4), [0, 0, 0, 1]]) for r in m])

    cases = [(1, "f", False), (3, "f", True), (1.5, "m", False), (1.5, "m", True), (5.0, "d", False)]
    n = check_all(ref, est, kitti_for_evo(tmp_path / "gt.txt"), kitti_for_evo(tmp_path / "est.txt"), rpe_cases=cases)
    assert n == len(ALIGNS) * (6 + 7 * len(cases))


def test_euroc_reader_reads_what_evo_reads(tmp_path):
    rng = np.random.default_rng(3)
    t, p, q = smooth_trajectory(rng, 50, t0=1403636579.0)
    ns = (t * 1e9).astype(np.int64)
    rows = [f"{a},{','.join(f'{v:.9f}' for v in (*pp, qq[3], *qq[:3]))},0,0,0,0,0,0,0,0,0"
            for a, pp, qq in zip(ns, p, q)]
    path = tmp_path / "data.csv"
    path.write_text("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], "
                    "q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], "
                    "b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], "
                    "b_a_RS_S_z [m s^-2]\n" + "\n".join(rows) + "\n")
    ours = load(str(path))
    m = np.loadtxt(path, delimiter=",")  # evo's read_euroc_csv_trajectory: t = ns / 1e9, quaternion w x y z
    np.testing.assert_array_equal(ours.t, m[:, 0] / 1e9)
    np.testing.assert_allclose(ours.p, m[:, 1:4], rtol=0, atol=0)
    np.testing.assert_allclose(np.roll(ours.q, 1, axis=1), m[:, 4:8] / np.linalg.norm(m[:, 4:8], axis=1)[:, None],
                               atol=1e-15)


@pytest.fixture(scope="module")
def ros_example(shared_dir):
    """(ours, evo's) trajectories of groundtruth, ORB-SLAM, S-PTAM; evo's read by rosbags as evo reads them."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = shared_dir / "datasets" / "bags" / "evo" / "ROS_example.bag"
    topics = ("groundtruth", "ORB-SLAM", "S-PTAM")
    raw = {k: ([], [], []) for k in topics}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS1_NOETIC)) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        for conn, _, data in reader.messages(connections=conns):
            m = reader.deserialize(data, conn.msgtype)
            t, xyz, q = raw[conn.topic]
            t.append(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9)
            xyz.append([m.pose.position.x, m.pose.position.y, m.pose.position.z])
            o = m.pose.orientation
            q.append([o.w, o.x, o.y, o.z])
    theirs = {k: PoseTrajectory3D(np.array(v[1]), np.array(v[2]), np.array(v[0])) for k, v in raw.items()}
    ours = {k: load(f"{path}:{k}") for k in topics}
    return ours, theirs


@pytest.mark.slow
@pytest.mark.parametrize("estimate", ["ORB-SLAM", "S-PTAM"])
def test_ros_example_bag_agrees_with_evo(ros_example, estimate):
    """Every alignment x relation for the APE and for the RPE over 1 m; further RPE deltas (1 frame,
    1 m all pairs, 5 deg) with SE(3)/Sim(3). evo takes about 1 ms per pose and angle: the matrix is
    trimmed where it would only repeat (angle_rad is angle_deg in other units)."""
    ours, theirs = ros_example
    args = ours["groundtruth"], ours[estimate], theirs["groundtruth"], theirs[estimate]
    cheap = [r for r in APE_RELATIONS if r != "angle_rad"]
    n = check(*args, aligns=ALIGNS, relations=cheap)
    n += check(*args, aligns=[("none", False), ("se3", False)], relations=["angle_rad"])
    n += check(*args, aligns=ALIGNS, relations=RPE_RELATIONS, case=(1.0, "m", False))
    for case in ((1, "f", False), (1.0, "m", True), (5.0, "d", False)):
        n += check(*args, aligns=[("se3", False), ("sim3", False)], relations=["trans", "angle_deg"], case=case)
    assert n == len(ALIGNS) * (len(cheap) + len(RPE_RELATIONS)) + 2 + 3 * 4


@pytest.mark.slow
def test_ros_example_orb_slam_se3_translation_rmse(ros_example):
    """The acceptance number: ``evo_ape bag ROS_example.bag groundtruth ORB-SLAM -a`` prints rmse 5.509938."""
    ours, _ = ros_example
    s = score(ours["groundtruth"], ours["ORB-SLAM"], align="se3")
    assert s.stats()["rmse"] == pytest.approx(5.509938, abs=5e-7)
    assert len(s.reference) == 2550
