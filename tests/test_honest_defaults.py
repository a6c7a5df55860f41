"""Honest defaults (issue 24 items 2 and 4): a recording is never scored on measurements drawn from
its reference without saying so; the raw observations' row shows a filter worse than its input."""
import csv

import pytest
from click.testing import CliRunner

from replay.cli import main

# the ROS 1 bags (test1.bag, test3_groovy.bag and ROS_example.bag: 5-20 s each) are slow: the fast
# subset keeps test1.bag's MCAP and SQLite conversions and an MCAP recording of another robot (nav2)
_SLOW = pytest.mark.slow
RECORDINGS = [pytest.param("robot_localization/test1.bag", marks=_SLOW),
              pytest.param("robot_localization/test3_groovy.bag", marks=_SLOW),
              "derived/rl_test1_60s_mcap", "derived/rl_test1_60s_sqlite3",
              pytest.param("evo/ROS_example.bag", marks=_SLOW), "evo/nav2_turtlebot.mcap"]


@pytest.mark.parametrize("rec", RECORDINGS)
def test_no_unmarked_synthetic_row_on_any_shared_recording(shared_dir, tmp_path, rec):
    """Without a mapping (the proposal) and without --task: the fusion task over the recording's
    sensors, or a one-line refusal, or rows that say they are synthetic — in the table and the CSV."""
    res = CliRunner().invoke(main, ["eval", str(shared_dir / "datasets" / "bags" / rec), "-f", "ekf", "--runs", "1",
                                    "--first", "1500", "-o", str(tmp_path / "o"), "-q"])
    if res.exit_code == 2:  # refused: no reference to score against
        assert "nothing to score against" in res.output and len(res.output.strip().splitlines()) == 1
        return
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(open(tmp_path / "o" / "leaderboard.csv")))
    assert rows and all(r["measurements"] in ("sensors", "synthetic", "recorded") for r in rows)
    synthetic = [r for r in rows if r["measurements"] == "synthetic"]
    assert not synthetic or "synthetic measurements: task" in res.output
    if rows[0]["task"] == "fusion":
        assert not synthetic and rows[0]["measurements"] == "sensors"


@pytest.mark.slow
def test_bohai_position_measurements_row_flags_the_pf(bohai_dir, tmp_path):
    """Bohai 0_6, whole log, 10 runs: the measurements (reference + N(0, 2 I)) score 2.45 m; the
    bootstrap PF loses every run (12.9 m) and is flagged worse than its own input; the EKF is not."""
    res = CliRunner().invoke(main, ["eval", "bohai/20220822_0_6", "--data-dir", str(bohai_dir), "--task", "position",
                                    "--runs", "10", "-f", "ekf,pf", "-o", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    rows = {r["filter"]: r for r in csv.DictReader(open(tmp_path / "o" / "leaderboard.csv"))}
    assert set(rows) == {"ekf", "pf", "measurements"}
    assert float(rows["measurements"]["pos_rmse"]) == pytest.approx(2.4466, abs=1e-3)
    assert rows["pf"]["worse_than_measurements"] == "True" and rows["ekf"]["worse_than_measurements"] == "False"
    assert ("worse than its own measurements (the measurements row: the raw observations, scored alike; paired "
            "over runs, ± the 95 % interval): pf (+") in res.output
    diff, half = map(float, rows["pf"]["worse_than_measurements_by"].split(" ± "))
    assert diff - half > 5  # the PF's paired excess over the raw observations, far outside its interval
    assert "reference: onboard solution" in res.output and "defaults (not tuned" in res.output
    assert all(r["measurements"] == "synthetic" for r in rows.values())


def test_an_error_far_beyond_lost_is_a_divergence_even_with_a_finite_covariance():
    """The AUKF case: 1.5e7 m off at one of three scored samples (too few to be called lost), with
    a finite covariance. Default threshold: 100 x the task's lost threshold (1000 m -> 1e5 m)."""
    import numpy as np

    from replay.scoring import metrics, scorer
    from replay.filters.base import Estimates
    from replay.model import LinearGaussian
    from replay.tasks import Problem, make_task

    n = 20
    truth = np.zeros((n, 2))
    valid = np.zeros(n, bool)
    valid[[5, 10, 15]] = True  # three resurfacing fixes
    prob = Problem(LinearGaussian(np.eye(2), np.eye(2), np.eye(2), np.eye(2)), np.zeros((n, 2)), np.zeros(2),
                   np.eye(2), np.arange(n, dtype=float), truth, valid, (0, 1), ("north", "east"))
    prob = make_task("dead-reckoning").judge(prob)
    assert prob.divergence_threshold == 100 * prob.lost_threshold == 1e5
    x = np.zeros((n, 2))
    x[10] = [1.5e7, 0.0]
    est = Estimates(x, np.tile(np.eye(2), (n, 1, 1)), np.zeros(n), None, {})
    m, _ = metrics.run_metrics(prob, est, "none", None, scorer.errors(prob, est))
    assert m["diverged"] is True and m["lost"] is None
    x[10] = [5e4, 0.0]  # beyond lost, within the divergence threshold: a result (lost: all 3 needed)
    m, _ = metrics.run_metrics(prob, est, "none", None, scorer.errors(prob, est))
    assert m["diverged"] is False
