"""``replay score --lengths``: rpg_trajectory_evaluation / KITTI relative errors over lengths, checked on
constructed cases with hand-computed answers, against a literal loop re-statement of rpg's definition,
for invariance to a rigid motion of the estimate, and through the CLI in one call."""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from replay.cli.main import main
from replay.cli.score import score_cmd
from replay.trajectory import lengths as L
from replay.trajectory import score
from replay.trajectory.base import Trajectory, make
from replay.trajectory.files import write_tum

if "score" not in main.commands:
    main.add_command(score_cmd)

ID = np.array([0.0, 0.0, 0.0, 1.0])


def line(n=201, ds=0.5, scale=1.0):
    """Poses every ds m along x, orientations identity; positions times ``scale``."""
    t = np.arange(n) * 0.1
    p = np.column_stack([np.arange(n) * ds * scale, np.zeros(n), np.zeros(n)])
    return Trajectory(t, p, np.tile(ID, (n, 1)), name="line")


def test_scale_error_gives_its_percentage_at_every_length():
    ref, est = line(), line(scale=1.05)
    s = score(ref, est, lengths="10,20,50%")
    assert list(s.lengths) == ["10m", "20m", "50%"]
    # rpg keeps every start whose nearest end is strictly within 20 % of the length: near the end of the
    # track the last pose, a shorter sub-trajectory, still divided by the nominal length
    for name, m, full, n in (("10m", 10.0, 181, 184), ("20m", 20.0, 161, 168), ("50%", 50.0, 101, 120)):
        e = s.lengths[name]
        i, j = e["pairs"]
        assert e["length"] == m and len(e["trans"]) == n
        np.testing.assert_array_equal(i, np.arange(n))
        np.testing.assert_array_equal(j, np.minimum(i + round(m / 0.5), 200))
        np.testing.assert_allclose(e["trans_perc"][:full], 5.0, rtol=1e-9)
        np.testing.assert_allclose(e["trans"], 0.05 * 0.5 * (j - i), rtol=1e-9)
        assert e["trans_perc"][-1] < 5.0
        for k in ("rot", "rot_deg_per_m", "yaw", "gravity"):
            assert np.max(e[k]) == 0.0
    # rpg scales the relative translation by the alignment's scale: the error vanishes (on a line
    # the fit is undetermined and refused: a random track scaled by 1.05)
    ref, _ = _random_pair()
    est = Trajectory(ref.t, 1.05 * ref.p, ref.q)
    s = score(ref, est, align="sim3", lengths="10,20")
    assert s.transform[2] == pytest.approx(1 / 1.05, rel=1e-12)
    assert np.max(s.lengths["10m"]["trans"]) < 1e-9 and np.max(s.lengths["20m"]["trans_perc"]) < 1e-9


def test_yaw_rate_bias_grows_linearly_with_length():
    """Dead reckoning with a heading drifting b rad/m: the relative yaw error over L is b L exactly;
    the translation error is |sum_m ds e^(i b m ds) - L| (a geometric series)."""
    n, ds, b = 401, 0.25, 0.004
    ref = line(n, ds)
    yaw = b * np.arange(n) * ds
    steps = ds * np.column_stack([np.cos(yaw[:-1]), np.sin(yaw[:-1]), np.zeros(n - 1)])
    p = np.vstack([[0.0, 0.0, 0.0], np.cumsum(steps, axis=0)])
    est = Trajectory(ref.t, p, Rotation.from_euler("z", yaw[:, None]).as_quat())
    s = score(ref, est, lengths="10,20,40")
    for m in (10.0, 20.0, 40.0):
        e = s.lengths[f"{m:g}m"]
        i, j = e["pairs"]
        full = j - i == round(m / ds)
        assert full.sum() == n - round(m / ds) and not full[-1]  # the shorter ends at the track's end (rpg)
        ell = (j - i) * ds  # travelled length of each sub-trajectory
        np.testing.assert_allclose(e["yaw"], np.degrees(b * ell), rtol=1e-9)
        np.testing.assert_allclose(e["rot"], np.degrees(b * ell), rtol=1e-6)  # arccos of the trace, as rpg
        np.testing.assert_allclose(e["rot_deg_per_m"][full], math.degrees(b), rtol=1e-6)
        assert np.max(e["gravity"]) < 1e-9
        N = round(m / ds)
        z = ds * (1 - np.exp(1j * b * ds * N)) / (1 - np.exp(1j * b * ds))
        np.testing.assert_allclose(e["trans"][full], abs(z - m), rtol=1e-7)
    y10, y40 = s.lengths["10m"]["yaw"][0], s.lengths["40m"]["yaw"][0]
    assert y40 == pytest.approx(4 * y10, rel=1e-12)


def _rpg_ends(p_gt, dist):
    """rpg's comparison indices, re-stated with a loop over starts (oracle)."""
    D = np.concatenate(([0.0], np.cumsum([math.sqrt(float(np.sum((p_gt[k] - p_gt[k - 1]) ** 2)))
                                          for k in range(1, len(p_gt))])))
    ends = []
    for a in range(len(D)):
        err = np.abs(D[a:] - (D[a] + dist))
        k = int(np.argmin(err))  # first of ties, as rpg's strict '<'
        if err[k] < 0.2 * dist:
            ends.append(a + k)
    return ends if len(ends) >= 2 else []


def _rpg_errors(p_gt, q_gt, p_es, q_es, ends, scale):
    """rpg's error per (k, ends[k]) with 4x4 matrices (oracle)."""
    def T(q, p):
        M = np.eye(4)
        M[:3, :3] = Rotation.from_quat(q).as_matrix()
        M[:3, 3] = p
        return M

    out = []
    for a, c in enumerate(ends):
        E12 = np.linalg.inv(T(q_es[a], p_es[a])) @ T(q_es[c], p_es[c])
        E12[:3, 3] *= scale
        G12 = np.linalg.inv(T(q_gt[a], p_gt[a])) @ T(q_gt[c], p_gt[c])
        Rc = np.eye(4)
        Rc[:3, :3] = T(q_es[c], p_es[c])[:3, :3]
        Ew = Rc @ np.linalg.inv(G12) @ E12 @ np.linalg.inv(Rc)
        yaw, pitch, roll = Rotation.from_matrix(Ew[:3, :3]).as_euler("ZYX")
        rot = math.degrees(math.acos(min(1, max(-1, (np.trace(Ew[:3, :3]) - 1) / 2))))
        out.append((np.linalg.norm(Ew[:3, 3]), rot, abs(math.degrees(yaw)), math.degrees(math.hypot(pitch, roll))))
    return out


def _rpg_loop(p_gt, q_gt, p_es, q_es, dist, scale):
    return _rpg_errors(p_gt, q_gt, p_es, q_es, _rpg_ends(p_gt, dist), scale)


def _random_pair(n=160, seed=3, gap=False):
    rng = np.random.default_rng(seed)
    p = np.cumsum(rng.normal(0, 0.3, (n, 3)) + [0.4, 0.1, 0.0], axis=0)
    if gap:
        p[80:] += [6.0, 0.0, 0.0]  # one 6 m step: starts before it find no end within 20 % of 10 m
    q = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.05, (n, 3)), axis=0)).as_quat()
    pe = p * 1.02 + rng.normal(0, 0.05, p.shape)
    qe = (Rotation.from_quat(q) * Rotation.from_rotvec(rng.normal(0, 0.02, (n, 3)))).as_quat()
    t = np.arange(n) * 0.1
    return Trajectory(t, p, q, name="gt"), Trajectory(t, pe, qe, name="est")


@pytest.mark.parametrize("gap", [False, True])
@pytest.mark.parametrize("align", ["none", "se3", "sim3"])
def test_equals_rpg_definition_loop_by_loop(align, gap):
    ref, est = _random_pair(gap=gap)
    s = score(ref, est, align=align, lengths="10,25")
    for name, m in (("10m", 10.0), ("25m", 25.0)):
        want = np.array(_rpg_loop(ref.p, ref.q, est.p, est.q, m, float(s.transform[2])))
        e = s.lengths[name]
        assert len(e["trans"]) == len(want) > 0
        for k, col in (("trans", 0), ("rot", 1), ("yaw", 2), ("gravity", 3)):
            np.testing.assert_allclose(e[k], want[:, col], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(e["trans_perc"], want[:, 0] / m * 100, rtol=1e-12)
    if gap:
        assert s.lengths["10m"]["gaps"] > 0


def test_invariant_to_a_rigid_motion_of_the_estimate():
    ref, est = _random_pair()
    base = score(ref, est, lengths="10,20")
    R = Rotation.from_euler("xyz", [0.3, -0.2, 1.1]).as_matrix()
    moved = est.transformed(R, np.array([5.0, -3.0, 2.0]))
    Rz = Rotation.from_euler("z", 2.0).as_matrix()
    yawed = est.transformed(Rz, np.array([1.0, 2.0, 3.0]))
    for other in (moved, yawed):
        for align in ("none", "se3"):
            s = score(ref, other, align=align, lengths="10,20")
            for name in ("10m", "20m"):
                for k in ("trans", "trans_perc", "rot", "rot_deg_per_m"):
                    np.testing.assert_allclose(s.lengths[name][k], base.lengths[name][k], rtol=1e-7, atol=1e-7)
    # yaw and gravity are split in the frame of the estimate as recorded (rpg): the alignment leaves them
    aligned = score(ref, moved, align="se3", lengths="10")
    unaligned = score(ref, moved, lengths="10")
    for k in L.ERRORS:
        np.testing.assert_array_equal(aligned.lengths["10m"][k], unaligned.lengths["10m"][k])


def test_kitti_definition_on_a_line():
    """Every 10th start; the end is the first pose whose distance EXCEEDS the length: with poses every
    metre, 101 m for 100 m, so a 5 % scale error reads 5.05 % of the nominal length (rpg: 5 %)."""
    ref, est = line(1001, 1.0), line(1001, 1.0, scale=1.05)
    s = score(ref, est, lengths="100,200,...,800", lengths_method="kitti")
    assert list(s.lengths) == [f"{k}m" for k in range(100, 900, 100)]
    for k in range(100, 900, 100):
        e = s.lengths[f"{k}m"]
        i, j = e["pairs"]
        np.testing.assert_array_equal(i, np.arange(0, 1000 - k, 10))
        np.testing.assert_array_equal(j, i + k + 1)
        np.testing.assert_allclose(e["trans_perc"], 5.0 * (k + 1) / k, rtol=1e-9)
    r = score(ref, est, lengths="100", lengths_method="rpg").lengths["100m"]
    np.testing.assert_allclose(r["trans_perc"][:901], 5.0, rtol=1e-9)
    assert len(r["trans"]) == 920  # and 19 shorter ones at the end, within 20 m of 100 m


def test_percentages_truncated_to_cm_and_range_syntax():
    assert L.resolve(L.parse("10%,50%"), 123.4567) == [("10%", 12.34), ("50%", 61.72)]
    assert [v for _, v in L.parse("100,200,...,800")] == [100.0 * k for k in range(1, 9)]
    assert L.parse("10%,20%,...,50%") == [("%", 10.0 * k) for k in range(1, 6)]


def _files(tmp_path):
    ref, est = line(), line(scale=1.05)
    write_tum(tmp_path / "gt.tum", make(ref.t + 100, ref.p, ref.q, source="gt"))
    write_tum(tmp_path / "est.tum", make(est.t + 100, est.p, est.q, source="est"))
    return tmp_path / "gt.tum", tmp_path / "est.tum"


def test_cli_one_call_prints_and_writes_one_row_per_length(tmp_path):
    gt, est = _files(tmp_path)
    out = tmp_path / "res.csv"
    r = CliRunner().invoke(main, ["score", str(gt), str(est), "--lengths", "10%,20%,30%,40%,50%", "-o", str(out)],
                           catch_exceptions=False)
    assert r.exit_code == 0, r.output
    assert "length 10% = 10 m: 184 sub-trajectories" in r.output
    assert "length 50% = 50 m: 120 sub-trajectories" in r.output
    with open(out) as f:
        rows = list(csv.DictReader(f))
    assert [row["length"] for row in rows] == ["10%", "20%", "30%", "40%", "50%"]
    assert [float(row["length_m"]) for row in rows] == [10.0, 20.0, 30.0, 40.0, 50.0]
    for row in rows:
        assert float(row["rel_trans_perc_max"]) == pytest.approx(5.0, rel=1e-9)
        assert row["lengths_method"] == "rpg" and row["filter"] == "recorded:est"
    assert [int(row["rel_trans_num_samples"]) for row in rows] == [184, 168, 152, 136, 120]


@pytest.mark.slow
def test_ros_example_orb_slam_equals_rpg_definition(shared_dir):
    """ROS_example.bag, ORB-SLAM against groundtruth, -a, 10-50 %: rpg's definition on real data."""
    from replay.trajectory import io

    bag = shared_dir / "datasets" / "bags" / "evo" / "ROS_example.bag"
    ref, est = io.load_all([f"{bag}:groundtruth", f"{bag}:ORB-SLAM"], names=["groundtruth", "ORB-SLAM"])
    s = score(ref, est, align="se3", lengths="10%,20%,30%,40%,50%")
    total = float(L.distances(ref.p)[-1])
    assert [e["length"] for e in s.lengths.values()] == [math.trunc(k / 10 * total * 100) / 100 for k in range(1, 6)]
    assert [len(e["trans"]) for e in s.lengths.values()] == [2293, 2031, 1794, 1547, 1369]
    r, e = s.reference, s.estimate
    for entry in s.lengths.values():
        ends = _rpg_ends(r.p, entry["length"])
        np.testing.assert_array_equal(entry["pairs"][1], ends)
        take = np.arange(0, len(ends), 25)
        want = np.array(_rpg_errors(r.p, r.q, e.p, e.q, ends, 1.0))[take]
        for k, col in (("trans", 0), ("rot", 1), ("yaw", 2), ("gravity", 3)):
            np.testing.assert_allclose(entry[k][take], want[:, col], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_rpg_ends_with_stationary_poses_and_ties(seed):
    """Plateaus of the path length (stationary poses) and rounded positions (ties): first of ties, as rpg."""
    ref, _ = _random_pair(seed=seed)
    p = ref.p.copy()
    for k in np.random.default_rng(seed).integers(1, len(p), 40):
        p[k] = p[k - 1]
    p = np.round(p, 1)
    for dist in (1.0, 3.0, 10.0, 25.0):
        _, j, _ = L.rpg_pairs(L.distances(p), dist, 0.2 * dist)
        assert list(j) == _rpg_ends(p, dist)
