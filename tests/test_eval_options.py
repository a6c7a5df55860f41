"""`replay eval --dataset-param` and `--baseline`, and the leaderboard's paired-comparison columns."""
from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli import main
from replay import evaluate  # the API: keywords in, one EvalOptions record built


def _eval(tmp_path, *args):
    out = tmp_path / "o"
    r = CliRunner().invoke(main, ["eval", "sim/ungm", "--task", "ungm", "--runs", "3", "-o", str(out), "--force", *args])
    return r, out


def test_dataset_param_reaches_the_simulator_and_manifest(tmp_path):
    r, out = _eval(tmp_path, "--filters", "ekf", "--dataset-param", "q=10", "--dataset-param", "r=10")
    assert r.exit_code == 0, r.output
    man = json.loads((out / "manifest.json").read_text())
    given = {k: man["config"]["dataset_params"][k] for k in ("q", "r")}
    assert given == {"q": 10, "r": 10}  # stored canonically: the other parameters with their defaults
    assert "--dataset-param q=10" in man["command"] and "--dataset-param r=10" in man["command"]
    assert man["dataset"]["simulation"]["params"]["q"] == 10.0 and man["dataset"]["simulation"]["params"]["r"] == 10.0
    ev = evaluate("sim/ungm", task="ungm", filters=("ekf",), runs=3, dataset_params={"q": 10, "r": 10})
    row = next(csv.DictReader(open(out / "leaderboard.csv")))
    assert float(row["pos_rmse"]) == pytest.approx(ev.results[0].summary["pos_rmse"], rel=1e-5)
    # Q = R = 10 is noisier than the default Q = R = 1
    ev1 = evaluate("sim/ungm", task="ungm", filters=("ekf",), runs=3)
    assert ev.results[0].summary["pos_rmse"] > ev1.results[0].summary["pos_rmse"]


def test_leaderboard_paired_columns_against_first_filter_and_baseline(tmp_path):
    r, out = _eval(tmp_path, "--filters", "ekf,ukf,pf", "-p", "pf.n_particles=100")
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader(open(out / "leaderboard.csv")))
    assert rows[0]["pos_rmse_vs_ekf"] == "" and rows[0]["pos_rmse_vs_ekf_ci95"] == ""
    ev = evaluate("sim/ungm", task="ungm", filters=("ekf", "ukf", "pf"), runs=3, filter_params={"pf": {"n_particles": 100}})
    base = np.array([m["pos_rmse"] for m in ev.results[0].runs])
    for row, res in zip(rows[1:], ev.results[1:]):
        d = np.array([m["pos_rmse"] for m in res.runs]) - base
        assert float(row["pos_rmse_vs_ekf"]) == pytest.approx(d.mean(), rel=1e-5)
        half = 4.302653 * d.std(ddof=1) / np.sqrt(3)  # Student t, 2 degrees of freedom
        assert float(row["pos_rmse_vs_ekf_ci95"]) == pytest.approx(half, rel=1e-5)
    r, out = _eval(tmp_path, "--filters", "ekf,ukf", "--baseline", "ukf")
    rows = list(csv.DictReader(open(out / "leaderboard.csv")))
    assert "pos_rmse_vs_ukf" in rows[0] and rows[1]["pos_rmse_vs_ukf"] == ""
    assert float(rows[0]["pos_rmse_vs_ukf"]) == pytest.approx(float(rows[0]["pos_rmse"]) - float(rows[1]["pos_rmse"]),
                                                               abs=2e-5)


@pytest.mark.parametrize("args,word", [
    (["--filters", "ekf", "--dataset-param", "q"], "--dataset-param"),
    (["--filters", "ekf", "--baseline", "pf"], "--baseline"),
])
@pytest.mark.slow
def test_bad_options_one_line(args, word):
    r = subprocess.run([sys.executable, "-m", "replay.cli", "eval", "sim/ungm", "--task", "ungm", *args,
                        "-o", "/tmp/never-written"], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0 and word in r.stderr


@pytest.mark.slow
def test_rerun_of_swarm_filters_reproduces(tmp_path):
    r, out = _eval(tmp_path, "--filters", "gwo-pf,pso-pf", "-p", "gwo-pf.n_particles=20", "-p", "gwo-pf.t_max=3",
                   "-p", "pso-pf.n_particles=20", "-p", "pso-pf.t_max=3", "--dataset-param", "q=10")
    assert r.exit_code == 0, r.output
    rr = CliRunner().invoke(main, ["rerun", str(out / "manifest.json")])
    assert rr.exit_code == 0, rr.output
    assert "reproduced" in rr.output
