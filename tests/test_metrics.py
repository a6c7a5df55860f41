"""NEES/NIS consistency, Umeyama alignment, ATE, drift, attitude error, paired comparisons."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from replay.scoring import align, metrics
from replay.filters import make_filter
from replay.model import LinearGaussian


def _cv_model(q_scale=1.0):
    dt = 0.5
    A = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1.0]])
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    Q = 0.05 * np.kron(np.eye(2), [[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    return LinearGaussian(A, C, Q * q_scale, np.diag([0.5, 0.8]))


@pytest.fixture(scope="module")
def ensemble():
    """200 runs of a constant-velocity target: truth, measurements, prior (x0 ~ N(x0_hat, P0))."""
    M, n = 200, 60
    model = _cv_model()
    rng = np.random.default_rng(7)
    P0 = np.diag([1.0, 0.5, 1.0, 0.5])
    x = rng.multivariate_normal(np.zeros(4), P0, size=M)
    truth, z = np.empty((M, n, 4)), np.empty((M, n, 2))
    Lq, Lr = np.linalg.cholesky(model.Q), np.linalg.cholesky(model.R)
    for k in range(n):
        x = x @ model.A.T + rng.standard_normal((M, 4)) @ Lq.T
        truth[:, k] = x
        z[:, k] = x @ model.C.T + rng.standard_normal((M, 2)) @ Lr.T
    return truth, z, np.zeros((M, 4)), np.broadcast_to(P0, (M, 4, 4)).copy()


def _nees_of(ensemble, q_scale):
    truth, z, x0, P0 = ensemble
    est = make_filter("kf").run_batch(_cv_model(q_scale), z, x0, P0, [None] * len(z))
    X, P = np.stack([e.x for e in est]), np.stack([e.P for e in est])
    nis = np.stack([e.info["nis"] for e in est])
    return metrics.nees(X - truth, P), nis


def test_nees_of_tuned_kf_inside_band_mistuned_outside(ensemble):
    nees, nis = _nees_of(ensemble, 1.0)
    c = metrics.consistency(nees, 4)
    lo, hi, dof = metrics.averaged_band(np.full(60, 4.0), np.full(60, 200.0), nees.mean(axis=0) / 4)
    assert (c["anees_lo"], c["anees_hi"]) == (lo, hi)
    assert 4 * 200 < dof < 4 * 200 * 60  # fewer than M T d: the NEES is correlated from step to step
    assert lo < c["anees"] < hi  # the time- and run-averaged ANEES inside its own band
    assert c["anees_inside"] >= 0.85  # ~95 % of the steps
    n = metrics.consistency(nis, 2, "anis")
    assert n["anis_lo"] < n["anis"] < n["anis_hi"] and n["anis_inside"] >= 0.85
    bad = metrics.consistency(_nees_of(ensemble, 0.1)[0], 4)
    assert bad["anees"] > hi and bad["anees_inside"] < 0.2


def test_nees_known_value_and_nan():
    e = np.array([[1.0, 2.0], [np.nan, 0.0]])
    P = np.array([np.diag([1.0, 4.0]), np.eye(2)])
    out = metrics.nees(e, P)
    assert out[0] == pytest.approx(2.0) and np.isnan(out[1])


@pytest.mark.parametrize("method,scale", [("se3", 1.0), ("sim3", 2.5)])
def test_umeyama_recovers_known_transform(method, scale):
    rng = np.random.default_rng(3)
    a = rng.normal(size=(500, 3)) * [50, 30, 5]
    R = Rotation.from_euler("zyx", [0.7, -0.2, 0.1]).as_matrix()
    t = np.array([10.0, -4.0, 2.0])
    b = scale * a @ R.T + t
    R2, t2, c2 = align.align(a, b, method)
    np.testing.assert_allclose(R2, R, atol=1e-9)
    np.testing.assert_allclose(t2, t, atol=1e-9)
    assert c2 == pytest.approx(scale, abs=1e-9)
    assert metrics.ate(a, b, method) < 1e-9
    assert metrics.ate(a, b, "none") > 1.0


def test_yaw_alignment_recovers_yaw_and_translation():
    rng = np.random.default_rng(4)
    a = rng.normal(size=(200, 3)) * 20
    R = Rotation.from_euler("z", 1.2).as_matrix()
    b = a @ R.T + [3.0, 4.0, -1.0]
    R2, t2, _ = align.align(a, b, "yaw")
    np.testing.assert_allclose(R2, R, atol=1e-12)
    np.testing.assert_allclose(t2, [3.0, 4.0, -1.0], atol=1e-9)
    # a roll is not a yaw: the 4-DOF alignment cannot remove it, SE(3) can
    b3 = a @ Rotation.from_euler("x", 0.3).as_matrix().T
    assert metrics.ate(a, b3, "yaw") > 1.0 > 1e-9 > metrics.ate(a, b3, "se3")


def test_drift_final_error_path_length():
    ref = np.array([[0.0, 0, 0], [3, 0, 0], [3, 4, 0]])
    assert metrics.path_length(ref) == 7.0
    assert metrics.path_length(np.vstack([ref, [np.nan] * 3])) == 7.0


def test_quaternion_angle_known_values():
    q1 = Rotation.from_euler("z", 0.3).as_quat(scalar_first=True)
    q2 = Rotation.from_euler("z", -0.2).as_quat(scalar_first=True)
    assert metrics.quat_angle(q1, q2) == pytest.approx(0.5, abs=1e-12)
    assert metrics.quat_angle(q1, -q1) == pytest.approx(0.0, abs=1e-12)  # q and -q: one rotation
    tiny = Rotation.from_rotvec([1e-9, 0, 0]).as_quat(scalar_first=True)
    assert metrics.quat_angle(tiny, [1.0, 0, 0, 0]) == pytest.approx(1e-9, rel=1e-6)


def test_paired_comparison_is_tighter_than_separate_intervals():
    rng = np.random.default_rng(5)
    common = rng.normal(10.0, 3.0, 100)  # run-to-run variation shared by both filters
    a, b = common + 0.1 + rng.normal(0, 0.05, 100), common + rng.normal(0, 0.05, 100)
    p = metrics.paired(a, b)
    assert p["n"] == 100 and abs(p["diff"] - 0.1) < 3 * p["diff_ci95"]
    assert p["diff_ci95"] < 0.05 < metrics.ci95(a)
    assert p["a_better"] < 0.1


def test_lost_track_needs_a_sustained_stretch_above_the_threshold():
    from replay.scoring.metrics import lost_track

    e = np.array([1.0, 30, 30, 30, 1, 30, 30, np.nan, 30, 30, 1])
    assert lost_track(e, None, 3) is None  # no rule: not judged
    assert lost_track(e, 20.0, 3) is True  # steps 1-3
    assert lost_track(e, 20.0, 4) is True  # steps 5, 6, (masked), 8, 9: NaN samples are skipped
    assert lost_track(e, 20.0, 5) is False
    assert lost_track(e, 40.0, 1) is False
    assert lost_track(np.array([25.0, 26.0]), 20.0, 10) is True  # shorter than lost_steps: all above
    assert lost_track(np.full(4, np.nan), 20.0, 2) is False


def test_share_above_counts_steps_whose_error_norm_exceeds_the_threshold():
    from replay.scoring.metrics import share_above

    err = np.array([[3.0, 4.0, 0.0], [1.0, 1.0, 1.0], [0.0, 0.0, 2.5], [np.nan, 0.0, 0.0]])  # norms 5, 1.73, 2.5, NaN
    assert share_above(err, 2.0) == 0.5  # 2 of 4 steps: the NaN step is not above but counts
    assert share_above(err, 1.0) == 0.75 and share_above(err, 5.0) == 0.0


def test_lost_tracks_are_counted_not_reported_as_success():
    """The README's first command: the bootstrap PF loses 2 of 20 tracks on sim/auv-sonar (errors of
    176.6 and 50.8 m); they are counted, shown beside a median, and dominate the mean."""
    from replay import evaluate  # the API: keywords in, one EvalOptions record built

    ev = evaluate("sim/auv-sonar", filters=("ekf", "pf"), runs=20, seed=0)
    ekf, pf = ev.rows
    assert ekf["lost"] == 0 and ekf["diverged"] == 0 and ekf["lost_share"] == 0.0
    assert pf["lost"] == 2 and pf["diverged"] == 0 and pf["lost_share"] > 0.5
    assert pf["pos_rmse_median"] < 4.0 < 14.0 < pf["pos_rmse"]
    lost = [r for r, m in enumerate(ev.results[1].runs) if m["lost"]]
    assert all(ev.results[1].runs[r]["pos_rmse"] > 20.0 for r in lost)
    assert ev.config["task_params"]["lost_threshold"] == 20.0  # the rule is recorded in the manifest


def test_consistency_flags_collapsed_covariance_and_hides_its_number():
    from replay.scoring.metrics import consistency

    rng = np.random.default_rng(3)
    good = rng.chisquare(3, size=(50, 200))                 # a consistent filter: NEES ~ chi2(3)
    out = consistency(good, 3, "anees")
    assert out["anees_flag"] == "consistent" and abs(out["anees"] - 3) < 0.1
    assert consistency(good * 4, 3, "anees")["anees_flag"] == "optimistic"
    assert consistency(good / 4, 3, "anees")["anees_flag"] == "pessimistic"
    neg = consistency(-good * 1e279, 3, "anees")           # P not positive definite: -4e+279 seen
    assert neg["anees_flag"] == "collapsed" and np.isnan(neg["anees"])
    bad = consistency(good * 1e230, 3, "anees")            # P shrunk to nothing: 1e+230-size NEES
    assert bad["anees_flag"] == "collapsed" and np.isnan(bad["anees"])
    edge = consistency(np.full((10, 5), 3e4 * 0.999), 3, "anees")   # just below 1e4 per dof
    assert edge["anees_flag"] == "optimistic" and edge["anees"] == pytest.approx(29970)


def test_collapsed_consistency_printed_as_word():
    from replay.scoring.summary import consistency_cell

    assert consistency_cell({"anees": float("nan"), "anees_flag": "collapsed"}) == "collapsed"
    assert consistency_cell({"anees": 3.14159, "anees_flag": "consistent"}) == "3.14"


def test_anees_band_uses_the_tasks_position_dimension():
    """A 1-D task's NEES is chi2(1): its band and verdict use 1 degree of freedom, not 3."""
    from replay.scoring.summary import ensemble

    rng = np.random.default_rng(4)
    cols = [{"nees": rng.chisquare(1, 300), "nis": rng.chisquare(1, 300), "nis_dof": np.ones(300)}
            for _ in range(40)]
    one = ensemble(cols, nees_dof=1)
    assert one["anees_flag"] == "consistent" and abs(one["anees"] - 1) < 0.05
    assert one["anees_lo"] < 1 < one["anees_hi"] < 1.5
    assert ensemble(cols, nees_dof=3)["anees_flag"] == "pessimistic"  # the old hard-coded 3 misjudged it


def test_stacked_axis_errors_and_window_growth():
    """Per-run diagnostics of an evaluation's error records: the stacked array, the absolute error per axis, and
    the growth of the RMS error norm between two windows of steps (NaN for the runs marked invalid)."""
    errors = [{"position": np.array([[3.0, -4.0], [0.0, 1.0], [6.0, 8.0], [0.0, -2.0]])}, {"position": np.ones((4, 2))}]
    assert metrics.stacked_errors(errors).shape == (2, 4, 2)
    ax = metrics.axis_errors(errors, ["x", "y"])
    assert np.array_equal(ax["y"], [[4.0, 1.0, 8.0, 2.0], [1.0, 1.0, 1.0, 1.0]])
    # run 0: norms 5, 1, 10, 2: RMS over steps 2-3 is sqrt(52), over 0-1 sqrt(13); run 1: no growth
    g = metrics.window_growth(metrics.stacked_errors(errors), (0, 2), (2, 4))
    assert g == pytest.approx([np.sqrt(52) - np.sqrt(13), 0.0])
    g = metrics.window_growth(np.array([[1.0, 3.0], [2.0, 2.0]]), (0, 1), (1, 2), invalid=[False, True])
    assert g[0] == 2.0 and np.isnan(g[1])
