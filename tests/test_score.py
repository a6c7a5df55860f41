"""Scorer: known values, masking, wrapping, Monte Carlo aggregation."""
import numpy as np
import pytest

from replay.scoring import scorer
from replay.filters.base import Estimates
from replay.tasks import Problem


def make_problem(truth, valid, angles=None):
    n = len(truth)
    return Problem(model=None, z=np.zeros((n, 3)), x0=np.zeros(5), P0=np.eye(5), t=np.arange(n),
                   truth_position=truth, truth_valid=valid, position_index=(0, 1, 2),
                   axis_names=("x", "y", "z"), truth_angles=angles or {},
                   angle_index={"yaw": 3} if angles else {})


def test_rmse_known_values_and_masking():
    truth = np.zeros((4, 3))
    x = np.zeros((4, 5))
    x[:, 0] = [3.0, 0.0, 0.0, 100.0]  # the 100 m error falls on a masked sample
    x[:, 1] = [4.0, 0.0, 0.0, 0.0]
    valid = np.array([True, True, True, False])
    est = Estimates(x, np.tile(np.eye(5), (4, 1, 1)), np.full(4, 1e-5))
    m = scorer.score_run(make_problem(truth, valid), est)
    assert m["pos_rmse"] == pytest.approx(np.sqrt(25 / 3))
    assert m["x_rmse"] == pytest.approx(np.sqrt(9 / 3))
    assert m["y_rmse"] == pytest.approx(np.sqrt(16 / 3))
    assert m["z_rmse"] == 0.0
    assert m["scored"] == 3 and m["masked"] == 1
    assert m["us_per_step"] == pytest.approx(10.0)


def test_angle_error_is_wrapped():
    truth = np.zeros((2, 3))
    x = np.zeros((2, 5))
    x[:, 3] = [np.pi - 0.01, -np.pi + 0.02]
    yaw_truth = np.array([-np.pi + 0.01, np.pi - 0.02])
    est = Estimates(x, np.tile(np.eye(5), (2, 1, 1)), np.ones(2))
    m = scorer.score_run(make_problem(truth, np.ones(2, bool), {"yaw": yaw_truth}), est)
    assert m["yaw_rmse"] == pytest.approx(np.sqrt((0.02**2 + 0.04**2) / 2))


def test_aggregate_mean_of_runs_and_interval():
    runs = [{"pos_rmse": v, "us_per_step": 1.0, "scored": 10, "masked": 0, "diverged": False}
            for v in (1.0, 2.0, 3.0)]
    runs.append({"pos_rmse": np.nan, "us_per_step": 1.0, "scored": 3, "masked": 0, "diverged": True})
    a = scorer.aggregate(runs)
    assert a["runs"] == 4 and a["diverged"] == 1
    assert a["pos_rmse"] == pytest.approx(2.0)
    # t(0.975, 2) = 4.302652729749464; sd = 1; n = 3
    assert a["pos_rmse_ci95"] == pytest.approx(4.302652729749464 / np.sqrt(3))


def test_rmse_over_time_across_runs():
    e1 = np.array([[1.0, 0, 0], [np.nan, np.nan, np.nan]])
    e2 = np.array([[3.0, 0, 0], [0.0, 2.0, 0]])
    curve = scorer.rmse_over_time([e1, e2])
    assert curve[0] == pytest.approx(np.sqrt(5.0))
    assert curve[1] == pytest.approx(2.0)  # the masked run is left out at that step


def test_score_where_scores_the_samples_of_a_time_mask_and_the_parts_combine():
    truth = np.zeros((5, 3))
    x = np.zeros((5, 5))
    x[:, 0] = [1.0, 2.0, 3.0, 100.0, 4.0]  # the 100 m error falls on a masked sample
    valid = np.array([True, True, True, False, True])
    est = Estimates(x, np.tile(np.eye(5), (5, 1, 1)), np.ones(5))
    problem = make_problem(truth, valid)
    keep = scorer.within(np.arange(5.0), [[0.5, 2.5, "dive"], [3.0, 3.5, "climb"]])  # [t0, t1) spans
    assert keep.tolist() == [False, True, True, True, False]
    assert not scorer.within(np.arange(5.0), []).any()
    a, b = scorer.score_where(problem, est, keep), scorer.score_where(problem, est, ~keep)
    assert a["x_rmse"] == pytest.approx(np.sqrt((4 + 9) / 2)) and (a["scored"], a["masked"]) == (2, 3)
    assert b["x_rmse"] == pytest.approx(np.sqrt((1 + 16) / 2)) and (b["scored"], b["masked"]) == (2, 3)
    whole = scorer.score_run(problem, est)["x_rmse"]
    assert whole == pytest.approx(np.sqrt((a["x_rmse"] ** 2 * 2 + b["x_rmse"] ** 2 * 2) / 4))
