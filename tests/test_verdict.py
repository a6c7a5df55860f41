"""The reproductions' shared leaderboard rows and the portability check of documents."""
import pytest

from replay.reproduce.tables import result_rows
from replay.util.portable import check_portable


def test_result_rows_show_median_lost_and_diverged():
    row = {"label": "pf", "pos_rmse": 14.7522, "pos_rmse_ci95": 18.5296, "pos_rmse_median": 3.4378,
           "lost": 2, "lost_share": 0.8, "runs": 20, "diverged": 0}
    t = result_rows([row])
    assert "| pf | 14.752 ± 18.530 | 3.438 | 2/20* | 0/20 |" in t


def test_machine_paths_refused(tmp_path):
    from pathlib import Path

    with pytest.raises(ValueError, match="machine-specific"):
        check_portable(f"see {Path.home()}/data", "doc")
    check_portable("see ../shared/datasets/bohai", "doc")


def _pos_rmse(job, ev):  # a reducer: what comes back from the worker instead of the evaluation
    return job.key, [r["pos_rmse"] for r in ev.rows]


@pytest.mark.parametrize("workers", ["1", "2"])
def test_evaluate_jobs_in_plan_order_and_reduced_in_the_worker(monkeypatch, workers):
    from replay.campaign.longest import Job, evaluate_jobs
    from replay import evaluate  # the API: keywords in, one EvalOptions record built

    monkeypatch.setenv("REPLAY_WORKERS", workers)
    data = {"steps": 30, "q": 0.3, "r": 2.0}
    jobs = [Job("b", "sim/linear", ("ukf",), data, runs=3), Job("a", "sim/linear", ("ekf", "ukf"), data, seed=1)]
    out = evaluate_jobs(jobs, 2, 5, quiet=True, reduce=_pos_rmse)
    assert list(out) == ["b", "a"]
    want = evaluate("sim/linear", filters=("ekf", "ukf"), runs=2, seed=6, dataset_params=data)
    assert out["a"] == ("a", [r["pos_rmse"] for r in want.rows])
    whole = evaluate_jobs(jobs[:1], 2, 5, quiet=True)["b"]
    assert [r["pos_rmse"] for r in whole.rows] == out["b"][1] and whole.rows[0]["runs"] == 3
    with pytest.raises(ValueError, match=r"jobs planned twice: \['b'\]"):
        evaluate_jobs(jobs + jobs[:1], 2, 5, quiet=True)
