"""Where the reference comes from, on every table and in the manifest (issue 35 items 1, 3 and 6):
test1.bag's reference is the GPS it feeds (every 5th /fix), Bohai's the vehicle's navigation solution
built from its GPS on the surface; a simulation's is its truth. The raw-measurement flag fires only on a
paired difference above zero with its interval, and only against an independent reference."""
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli import main
from replay.scoring import provenance, summary
from replay.scoring.record import RunRecord

MAPPINGS = Path(__file__).resolve().parents[1] / "docs" / "mappings"


def _eval(*args):
    res = CliRunner().invoke(main, ["eval", *map(str, args)])
    assert res.exit_code == 0, res.output
    return res.output


def _manifest(out):
    return json.loads((out / "manifest.json").read_text())


def test_a_simulation_scores_against_its_truth_at_defaults(tmp_path):
    text = _eval("sim/linear", "-f", "kf", "--runs", 2, "-q", "-o", tmp_path / "o")
    head = text.split("\nfilter ")[0]
    assert "reference: simulated truth (the simulator's true state)" in head
    assert "filters: defaults (not tuned" in head and "shares a source" not in head
    rec = _manifest(tmp_path / "o")["dataset"]["reference"]
    assert rec == {"kind": "simulated truth", "source": "the simulator's true state", "independent": True,
                   "shares": ""}
    assert _manifest(tmp_path / "o")["results"]["kf"]["reference"] == "simulated truth"
    from replay.outputs.report import make_report

    assert "<p class='note'>reference: simulated truth</p>" in make_report(tmp_path / "o").read_text()
    given = _eval("sim/linear", "-f", "kf", "--runs", 2, "-q", "-p", "kf.q_scale=2", "-o", tmp_path / "p")
    assert "defaults (not tuned" not in given  # a parameter set by hand is not the defaults


def test_test1_says_the_reference_is_the_fed_gps_and_drops_the_flag(shared_dir, tmp_path):
    bag = shared_dir / "datasets" / "bags" / "robot_localization" / "test1.bag"
    text = _eval(bag, "--mapping", MAPPINGS / "rl_test1_fusion.toml", "--task", "fusion", "-f", "ekf", "--runs", 1,
                 "--first", 3000, "-q", "-o", tmp_path / "o")
    head = text.split("\nfilter ")[0]
    assert "reference: fed sensor (topic /fix)" in head
    assert ("reference shares a source with a fed input: gps.position (the same topic /fix: every 5th fix is fed, "
            "the others are withheld and scored)") in head
    assert "what is compared: each filter and the measurements row (the last fed fix held)" in head
    assert "worse than its own measurements" not in text and "(ref=input)" not in text  # held-out fixes only
    man = _manifest(tmp_path / "o")
    assert man["dataset"]["reference"]["kind"] == "fed sensor" and man["dataset"]["reference"]["independent"] is False
    for name in ("ekf", "measurements"):
        assert man["results"][name]["reference_shares"].startswith("gps.position (the same topic /fix")
    assert man["results"]["ekf"]["worse_than_measurements"] == ""


def test_bohai_says_the_reference_is_the_navigation_solution_built_from_the_fed_gps(bohai_dir, tmp_path):
    text = _eval("bohai/20220822_0_6", "--data-dir", bohai_dir, "-f", "ekf", "--runs", 1, "--first", 2000, "-q",
                 "-o", tmp_path / "o")
    head = text.split("\nfilter ")[0]
    assert "reference: onboard solution (the vehicle's navigation solution" in head
    assert ("reference shares a source with a fed input: gps_position.position (the navigation solution is built "
            "from the GPS fixes on the surface)") in head
    assert "what is compared: an error is the distance to a solution built from a fed input" in head
    assert "worse than its own measurements" not in text
    rec = _manifest(tmp_path / "o")["dataset"]["reference"]
    assert rec["kind"] == "onboard solution" and rec["shares"].startswith("gps_position.position")


def test_provenance_of_a_declared_source_and_of_a_bag_topic():
    """Another reference source (a smoothed track) fills the same record through the frame's meta."""
    meta = {"reference_provenance": {"kind": "smoothed track", "source": "RTS over the recording's sensors",
                                     "built_from": {"dvl": "smoothed from the DVL", "gps": "from the fixes"}}}
    inputs = {"dvl.velocity": "dvl (twist)", "imu.gyro": "imu (rates)", "reference": "position (...)"}
    rec = provenance.provenance(meta, inputs, {}, simulated=False, synthetic=False)
    assert rec["kind"] == "smoothed track" and rec["shares"] == "dvl.velocity (smoothed from the DVL)"
    assert rec["independent"] is False and "compared" in rec
    bag = {"mapping": {"entries": [{"name": "gps", "topic": "/fix"}, {"name": "odom", "topic": "/odom"},
                                   {"name": "position", "topic": "/truth", "reference": True}]}}
    rec = provenance.provenance(bag, {"odom.velocity": "odom (twist)"}, {}, simulated=False, synthetic=False)
    assert rec == {"kind": "recorded reference", "source": "topic /truth", "independent": True, "shares": ""}
    assert provenance.header(rec) == [
        "reference: recorded reference (topic /truth); its independence of the inputs is not declared"]


def _records(values):
    return [RunRecord(i, "done", {"diverged": False, "pos_rmse": v}) for i, v in enumerate(values)]


def _flag(filter_rmse, meas_rmse, shares=""):
    cfg = {"dataset": "d", "dataset_params": {}, "first": None, "task": "t", "task_params": {}, "seed": 0}
    rows = [{"filter": "ekf", "config_hash": "a", "pos_rmse": float(np.mean(filter_rmse))},
            {"filter": "measurements", "config_hash": "b", "pos_rmse": float(np.mean(meas_rmse))}]
    if shares:
        rows[0]["reference_shares"] = rows[1]["reference_shares"] = shares
    records = {"a": _records(filter_rmse), "b": _records(meas_rmse)}
    return summary.against_measurements(rows, {"a": cfg, "b": cfg}, records)[0]


def test_the_flag_needs_a_significant_paired_difference_and_an_independent_reference():
    base = [1.0785] * 5  # a deterministic filter: five identical runs
    assert _flag([v + 1.3e-13 for v in base], base)["worse_than_measurements"] is False  # rounding, not worse
    worse = _flag([1.2, 1.3, 1.25, 1.22, 1.28], [1.0, 1.1, 1.05, 1.02, 1.08])  # +0.2 in every run
    assert worse["worse_than_measurements"] is True and worse["worse_than_measurements_by"] == "0.2 ± 0"
    noisy = _flag([1.3, 0.9, 1.2, 0.95, 1.1], [1.0, 1.1, 1.05, 1.02, 1.08])  # +0.02 on average, within its interval
    assert noisy["worse_than_measurements"] is False
    assert _flag([1.0] * 3, [0.5] * 3, shares="gps.position (the same topic)")["worse_than_measurements"] == ""
    assert _flag([1.0], [0.5])["worse_than_measurements"] == ""  # one run: no interval, no judgement


def test_the_tune_board_names_the_reference():
    from replay.tune.write import board_notes

    rows = [{"label": f"ekf ({k})", "filter": "ekf", "test_score": 1.0, "train_score": 1.0,
             "reference": "onboard solution", "reference_shares": "gps_position.position (built from the GPS)"}
            for k in ("default", "tuned")]
    notes = board_notes(rows)
    assert notes[:2] == ["reference: onboard solution",
                         "reference shares a source with a fed input: gps_position.position (built from the GPS)"]


def test_a_task_that_scores_against_the_withheld_fixes_says_so(bohai_dir, tmp_path):
    """dead-reckoning with score=fixes: the reference is the GPS's first fix after each dive, withheld."""
    text = _eval("bohai/20220822_0_6", "--data-dir", bohai_dir, "--task", "dead-reckoning", "--task-param",
                 "score=fixes", "-f", "ekf", "--runs", 1, "-q", "-o", tmp_path / "o")
    head = text.split("\nfilter ")[0]
    assert "reference: fed sensor (the first GPS fix after each dive, withheld from the filters)" in head
    assert "reference shares a source with a fed input: gps (the same GPS: its other fixes are fed)" in head
    assert "what is compared: each filter's error at the resurfacing fixes it was not given" in head


def test_the_campaign_table_names_the_reference():
    from replay.campaign.board import format_rows

    row = {"dataset": "bohai/x", "task": "fusion", "filter": "ekf", "label": "ekf", "pos_rmse": 1.0, "runs": 1,
           "diverged": 0, "lost": 0, "reference": "onboard solution", "reference_shares": "gps_position.position (b)"}
    text = format_rows([row, dict(row, dataset="sim/y", reference="simulated truth", reference_shares="")])
    head, first, second, note = text.splitlines()
    assert head.split()[-1] == "reference" and first.endswith("onboard solution (shares an input)")
    assert second.endswith("simulated truth")
    assert note == "bohai/x: the reference shares a source with a fed input: gps_position.position (b)"
