"""The command line as a user meets it: outputs written, runs repeatable, bad input one line."""
import csv
import json
import subprocess
import sys

import pytest
from click.testing import CliRunner

from replay.cli import main


def run_cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "replay.cli", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_eval_sim_writes_leaderboard_and_manifest(tmp_path):
    out = tmp_path / "run"
    res = CliRunner().invoke(main, ["eval", "sim/auv-sonar", "--runs", "3", "--seed", "5",
                                    "-p", "pf.n_particles=200", "-o", str(out)])
    assert res.exit_code == 0, res.output
    for name in ("ekf", "ukf", "ckf", "pf"):
        assert f"\n{name} " in res.output
    rows = list(csv.DictReader(open(out / "leaderboard.csv")))
    assert [r["filter"] for r in rows] == ["ekf", "ukf", "ckf", "pf"]  # range and bearing: no measurements row
    assert all(r["runs"] == "3" and r["seed"] == "5" and r["task"] == "sonar" for r in rows)
    # The Kalman-type filters track the simulated AUV to a few metres on Table 2's setup.
    for r in rows[:3]:
        assert 0.5 < float(r["pos_rmse"]) < 5.0
        assert float(r["yaw_rmse"]) < 0.5
    man = json.loads((out / "manifest.json").read_text())
    assert man["config"]["filter_params"]["pf"]["n_particles"] == 200
    assert man["command"].startswith("replay eval sim/auv-sonar --task sonar")
    assert (out / "estimates" / "ukf.csv.gz").stat().st_size > 0
    # Repeating from the manifest gives the same numbers exactly.
    res2 = CliRunner().invoke(main, ["rerun", str(out / "manifest.json")])
    assert res2.exit_code == 0, res2.output
    assert "reproduced" in res2.output


def test_same_seed_same_numbers_other_seed_other_numbers(tmp_path):
    from replay import evaluate  # the API: keywords in, one EvalOptions record built

    a = evaluate("sim/auv-sonar", filters=["ukf"], runs=2, seed=1)
    b = evaluate("sim/auv-sonar", filters=["ukf"], runs=2, seed=1)
    c = evaluate("sim/auv-sonar", filters=["ukf"], runs=2, seed=2)
    assert a.results[0].summary["pos_rmse"] == b.results[0].summary["pos_rmse"]
    assert a.results[0].summary["pos_rmse"] != c.results[0].summary["pos_rmse"]


def test_adding_a_filter_changes_no_other_filter():
    from replay import evaluate  # the API: keywords in, one EvalOptions record built

    a = evaluate("sim/auv-sonar", filters=["ukf"], runs=2, seed=3)
    b = evaluate("sim/auv-sonar", filters=["pf", "ekf", "ukf"], runs=2, seed=3,
                 filter_params={"pf": {"n_particles": 50}})
    assert a.results[0].summary["pos_rmse"] == b.results[2].summary["pos_rmse"]


@pytest.mark.parametrize("args, expected", [
    (["eval", "sim/no-such"], "unknown dataset"),
    (["eval", "sim/auv-sonar", "--filters", "ukf,nope"], "unknown filter 'nope'"),
    (["eval", "sim/auv-sonar", "-p", "pf.bogus=1"], "filter 'pf'"),
    (["eval", "sim/auv-sonar", "--task", "nope"], "unknown task 'nope'"),
    (["eval", "/nonexistent/log.csv"], "/nonexistent/log.csv"),
])
@pytest.mark.slow
def test_bad_input_is_one_line_and_exit_2(args, expected, tmp_path):
    res = run_cli(*args, "-o", str(tmp_path / "o"), cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, res.stderr
    assert expected.lower() in lines[0].lower()


@pytest.mark.slow
def test_eval_bohai_position_first_1000(bohai_dir, tmp_path):
    """Slow: four filters x 3 runs on 1000 Bohai rows (6-25 s); the fast subset keeps
    tests/test_fusion.py::test_bohai_fusion_runs_through_its_sensor_columns (an eval of the same log),
    tests/test_bohai.py (its loading) and test_eval_sim_writes_leaderboard_and_manifest (the
    leaderboard's columns)."""
    out = tmp_path / "b"
    res = CliRunner().invoke(main, ["eval", "bohai/20220822_0_6", "--data-dir", str(bohai_dir), "--task",
                                    "position", "--first", "1000", "--runs", "3", "-o", str(out),
                                    "-p", "pf.n_particles=300"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(open(out / "leaderboard.csv")))
    assert [r["filter"] for r in rows] == ["ekf", "ukf", "ckf", "pf", "measurements"]  # the raw fixes' row
    for r in rows:
        assert r["first"] == "1000" and r["runs"] == "3" and int(r["scored"]) + int(r["masked"]) == 1000
    for r in rows[:4]:
        # Random walk Q = I observed with R = 2 I: the steady-state posterior sd per axis is
        # about 0.8 m, so the 3-D RMSE sits near 1.4 m; masked reference samples are skipped.
        assert 1.2 < float(r["pos_rmse"]) < 1.7 and r["worse_than_measurements"] == "False"
    # the measurements themselves: sqrt(3 * 2) = 2.449 m
    assert 2.3 < float(rows[4]["pos_rmse"]) < 2.6 and rows[4]["measurements"] == "synthetic"
    # Linear-Gaussian task: the three Kalman variants agree to rounding.
    assert float(rows[0]["pos_rmse"]) == pytest.approx(float(rows[1]["pos_rmse"]), rel=1e-12) == float(rows[2]["pos_rmse"])
    man = json.loads((out / "manifest.json").read_text())
    assert man["config"]["dataset_sha256"] == man["dataset"]["sha256"]
    assert man["dataset"]["crs"] == "EPSG:32651"


def test_datasets_list_shows_presence(bohai_dir):
    res = CliRunner().invoke(main, ["datasets", "list", "--data-dir", str(bohai_dir)])
    assert res.exit_code == 0, res.output
    lines = {line.split()[0]: line for line in res.output.splitlines()[1:]}
    assert sum(k.startswith("bohai/") for k in lines) == 17
    assert str(bohai_dir / "20220822_0_6.csv") in lines["bohai/20220822_0_6"]
    assert "missing" in lines["bohai/20220822_0_7"]


@pytest.mark.parametrize("content, expected", [
    ("", "empty"),
    ("lat,lon\n1,2\n", "missing"),
])
@pytest.mark.slow
def test_bad_csv_via_cli(tmp_path, content, expected):
    bad = tmp_path / "bad.csv"
    bad.write_text(content)
    res = run_cli("eval", str(bad), "-o", str(tmp_path / "o"), cwd=tmp_path)
    assert res.returncode == 2 and "Traceback" not in res.stderr
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "bad.csv" in lines[0] and expected in lines[0].lower()


def test_list_filters_shows_every_registered_filter_with_parameters():
    from replay.filters import FILTERS

    res = CliRunner().invoke(main, ["list", "filters"])
    assert res.exit_code == 0, res.output
    names = {line.split()[0] for line in res.output.splitlines() if not line.startswith(" ")}
    assert names == set(FILTERS)
    assert "\n    n_particles = 1000: an integer >= 1. " in res.output


@pytest.mark.parametrize("kind", ["filters", "tasks", "adapters", "datasets", "reproductions"])
def test_list_is_plain_text(kind):
    res = CliRunner().invoke(main, ["list", kind])
    assert res.exit_code == 0, res.output
    for markup in ("``", ":mod:", ":class:", ":func:", ":data:"):
        assert markup not in res.output, (kind, markup)


def test_list_tasks_and_datasets_show_declarations():
    res = CliRunner().invoke(main, ["list", "tasks", "position"])
    assert res.exit_code == 0, res.output
    assert res.output.splitlines() == [
        "position  the Bohai experiment of paper 002 (benchmark 3), as the digest reads it.",
        "    q = 1.0 [m^2]: a finite number > 0. process noise variance per axis and sample (Q = q I3)",
        "    r = 2.0 [m^2]: a finite number > 0. measurement noise variance per axis (R = r I3; 002 prints 2)",
        "    p0 = 0.1 [m^2]: a finite number > 0. prior variance per axis (P0 = p0 I3)",
        "    z0 = null [m]: a finite number (or null). constant vertical position; null = minus the first GPS "
        "altitude",
        "    lost_threshold = 10.0 [m]: a finite number > 0. a run whose position error stays above this for "
        "lost_steps consecutive scored samples is counted lost",
        "    lost_steps = 10: an integer >= 1. consecutive scored samples above lost_threshold that make a run "
        "lost"]
    res = CliRunner().invoke(main, ["list", "datasets", "sim/ungm"])
    assert "    q = 1.0: a finite number > 0. process noise variance Q (002 §3.2: 1 or 10)" in res.output
    res = run_cli("list", "tasks", "nope")
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "no task 'nope' (known: " in res.stderr


def test_lake_log_is_recognised_without_adapter_option(tmp_path):
    log = tmp_path / "lake.csv"
    res = CliRunner().invoke(main, ["datasets", "make", "sim/lake-depth", "--out", str(log)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["eval", str(log), "--filters", "ekf", "-o", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    row = next(csv.DictReader(open(tmp_path / "o" / "leaderboard.csv")))
    assert row["task"] == "depth" and 0.0 < float(row["depth_rmse"]) < 0.5
