"""Intervals that include tuning (issue 35 items 3 and 4): repeated tunes with other sampler seeds
(replay.tune.repeat), ``replay eval --tune N``; two identical filters are not called different."""
import csv

import numpy as np
import pytest
from click.testing import CliRunner
from scipy import stats

from replay.cli import main as cli
from replay.scoring.significance import paired_t
from replay.tune import check, repeat
from replay.tune.options import TuneOptions
from replay.tune.space import entries_from_cli


def test_interval_is_over_the_per_tune_means():
    x = np.array([[1.0, 2.0, 3.0], [2.0, 2.0, 2.0], [4.0, 5.0, 6.0]])
    mean, half = repeat.interval(x)
    m = x.mean(axis=1)
    assert mean == pytest.approx(m.mean()) and half == pytest.approx(stats.t.ppf(0.975, 2) * m.std(ddof=1) / 3**0.5)
    p = repeat.compare(x, x - 0.5, "a", "b")
    assert p["difference"] == pytest.approx(0.5) and p["ci95"] == 0.0 and p["different"]


@pytest.mark.slow
def test_two_identical_filters_are_not_called_different(tmp_path):
    """kf and ekf on the linear task are the same filter: after tuning, their gap is the optimiser's.
    Within one tune a paired test over its runs calls it significant; over 3 tunes x runs it is not.
    Slow: 3 tunes x 12 trials x 4 runs (20-40 s); the fast subset keeps
    test_interval_is_over_the_per_tune_means (the interval's arithmetic) and
    test_eval_tune_writes_tuned_rows_with_tuning_intervals (the tunes' intervals end to end)."""
    dims = ["log[0.01,10]", "log[0.1,20]"]
    entries = entries_from_cli([f"{f}.{p}={d}" for f in ("kf", "ekf") for p, d in zip(("q_scale", "r_scale"), dims)])
    t = check.prepare(TuneOptions(dataset="sim/linear", filters=["kf", "ekf"], entries=entries, trials=12,
                                  objective="mean_rmse", runs=4, seed=0, dataset_params={"steps": 100}, split="seeds"))
    res = repeat.run_repeats(t, tmp_path / "rep", 3, quiet=True)
    (pair,) = res["pairs"]
    assert not pair["different"] and pair["ci95"] > abs(pair["difference"]), pair
    xa, xb = res["X"][("kf", "tuned")], res["X"][("ekf", "tuned")]
    assert xa.shape == xb.shape == (3, 4)
    _, p_one_tune = paired_t(xa[0], xb[0], "two-sided")
    assert p_one_tune < 0.05  # the runs-only interval of one tune would call them different
    default = [r for r in res["rows"] if r["kind"] == "default"]
    assert default[0]["pos_rmse"] == default[1]["pos_rmse"]  # same filter, same runs
    assert any("not distinguishable" in line for line in repeat.ranking(res))


# slow: two tunes of two filters through the CLI
@pytest.mark.slow
def test_eval_tune_writes_tuned_rows_with_tuning_intervals(tmp_path):
    out = tmp_path / "tuned"
    r = CliRunner().invoke(cli, ["eval", "sim/linear", "-f", "kf,ukf", "--tune", "4", "--tune-repeats", "2", "-n", "2",
                                 "--dataset-param", "steps=60", "--out", str(out), "-q"])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader(open(out / "tuned.csv")))
    tuned = [x for x in rows if x["kind"] == "tuned"]
    assert [x["filter"] for x in tuned] == ["kf", "ukf"] and all(x["tunes"] == "2" for x in tuned)
    assert all(np.isfinite(float(x["ci95"])) and float(x["ci95"]) > 0 for x in tuned)
    assert "q_scale" in tuned[0]["params"] and (out / "tune-1" / "leaderboard.csv").is_file()
    assert "kf (tuned)" in r.output and (out / "ranking.csv").is_file()


@pytest.mark.parametrize("args, message", [
    (["--tune", "3"], "--tune: give --out DIR"),
    (["--tune-repeats", "3"], "go with --tune N"),
    (["--tune-grid", "3"], "go with --tune N"),
    (["--tune", "3", "--tune-repeats", "1", "--out", "X"], "at least 2 tunes"),
    (["--tune", "3", "-p", "kf.q_scale=2", "--out", "X"], "--params not taken with --tune"),
])
def test_eval_tune_refusals(tmp_path, args, message):
    args = [a.replace("X", str(tmp_path / "o")) for a in args]
    r = CliRunner().invoke(cli, ["eval", "sim/linear", "-f", "kf", *args])
    assert r.exit_code != 0 and message in r.output and "Traceback" not in r.output, r.output


@pytest.mark.slow
def test_grid_distance_on_the_linear_task(tmp_path):
    """nll fixes both q and r: the grid optimum of 9 x 9 points (log steps of 0.375 and 0.29 decades)
    lies near the truth (q 0.3, r 2), and 16 TPE trials reach its training score within 5 %.
    Slow: 81 grid points and 2 x 16 trials (20 s); the fast subset keeps tests/test_tune_grid.py (the
    grid's points and optimum) and test_eval_tune_writes_tuned_rows_with_tuning_intervals."""
    out = tmp_path / "g"
    r = CliRunner().invoke(cli, ["eval", "sim/linear", "-f", "kf", "--tune", "16", "--tune-repeats", "2", "-n", "4",
                                 "--dataset-param", "steps=100", "--out", str(out), "-q", "--tune-grid", "9",
                                 "--tune-space", str(_space(tmp_path)), "--tune-objective", "nll"])
    assert r.exit_code == 0, r.output
    line = next(x for x in r.output.splitlines() if x.startswith("kf: grid optimum (81 points)"))
    q = float(line.split("q_scale ")[1].split(",")[0])
    rr = float(line.split("r_scale ")[1].split(":")[0])
    assert 0.1 < q < 1.0 and 1.0 < rr < 4.0, line
    gap = float(line.split("(gap ")[1].split(")")[0])
    tuned = float(line.split("tune 0 ")[1].split(" ")[0])
    assert abs(gap) < 0.05 * tuned and "q_scale/r_scale" in line


def _space(tmp_path):
    p = tmp_path / "space.toml"
    p.write_text('[kf]\nq_scale = "log[0.01, 10]"\nr_scale = "log[0.1, 20]"\n')
    return p
