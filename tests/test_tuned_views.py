"""``replay eval --tuned`` evaluates on the data the tune tested on (issue 40 item 1): its views,
runs and seed, so that the command alone gives the tune's held-out rows; a view the command line
gives otherwise is refused in one line."""
import csv
import json

import pytest
from click.testing import CliRunner

from replay.cli import main

TUNE = ["tune", "sim/lake-depth", "--filters", "ekf", "--rate", "4", "--train-segment", "0.6",
        "-p", "ekf.q_scale=log[0.01,10]", "--runs", "2", "--trials", "3", "--seed", "5", "-q"]
COLS = ("pos_rmse", "pos_rmse_median", "ate", "final_err", "nees", "anees", "scored")


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    out = tmp_path_factory.mktemp("tune") / "t"
    res = CliRunner().invoke(main, [*TUNE, "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


def _eval(tmp_path, name, *args):
    return CliRunner().invoke(main, ["eval", "sim/lake-depth", *args, "-q", "--out", str(tmp_path / name)])


def _results(path):
    return json.loads((path / "manifest.json").read_text())


def test_eval_tuned_alone_gives_the_held_out_rows_exactly(tuned, tmp_path):
    from replay.campaign import board as cboard

    with open(tuned / "leaderboard.csv", newline="") as fh:
        row = [r for r in csv.DictReader(fh) if r["label"] == "ekf (tuned)"][0]
    res = _eval(tmp_path, "e", "--tuned", str(tuned / "tuned.toml"))
    assert res.exit_code == 0, res.output
    m = _results(tmp_path / "e")
    assert m["config"]["dataset_params"]["rate"] == 4.0 and m["config"]["dataset_params"]["segment"] == "0.6:1"
    assert m["config"]["runs"] == 2 and m["config"]["seed"] == 5  # the tune's, not eval's defaults (10, 0)
    ev = m["results"]["ekf"]
    assert ev["config_hash"] == row["test_config_hashes"]
    held = {r["config_hash"]: r for r in cboard.campaign_rows(tuned)}[row["test_config_hashes"]]
    for col in COLS:
        assert float(ev[col]) == float(held[col]), col  # bitwise: the same configuration and runs
    # the same views given by hand agree (accepted), and give the same rows
    res = _eval(tmp_path, "h", "--tuned", str(tuned / "tuned.toml"), "--rate", "4", "--segment", "0.6:1")
    assert res.exit_code == 0, res.output
    assert _results(tmp_path / "h")["results"]["ekf"]["pos_rmse"] == ev["pos_rmse"]
    # the full log (what --tuned ran before): other numbers
    res = _eval(tmp_path, "full", "-f", "ekf", "-p", f"ekf.q_scale={json.loads(row['params'])['q_scale']!r}",
                "--runs", "2", "--seed", "5")
    assert res.exit_code == 0, res.output
    assert _results(tmp_path / "full")["results"]["ekf"]["pos_rmse"] != ev["pos_rmse"]


@pytest.mark.parametrize("args, says", [
    (["--rate", "10"], "the tune tested on rate=4.0 for sim/lake-depth, the command line gives rate=10.0"),
    (["--segment", "0:0.6"], "the tune tested on segment=0.6:1 for sim/lake-depth, the command line gives segment=0:0.6"),
    (["--window", "0:50"], "the tune tested on no window for sim/lake-depth"),
    (["--dataset-param", "duration=60"], "the tune tested on duration=90.0"),
    (["--first", "100"], "the tune tested on first=None for sim/lake-depth, the command line gives --first 100"),
])
def test_a_view_the_command_line_gives_otherwise_is_refused_in_one_line(tuned, tmp_path, args, says):
    res = _eval(tmp_path, "x", "--tuned", str(tuned / "tuned.toml"), *args)
    assert res.exit_code == 2, res.output
    line = res.output.strip()
    assert line.startswith("replay: error: --tuned ") and "\n" not in line and says in line, line
    assert not (tmp_path / "x").exists()


def test_explicit_runs_and_seed_win_and_another_dataset_is_noted(tuned, tmp_path):
    res = _eval(tmp_path, "r", "--tuned", str(tuned / "tuned.toml"), "--runs", "3", "--seed", "1")
    assert res.exit_code == 0, res.output
    m = _results(tmp_path / "r")
    assert (m["config"]["runs"], m["config"]["seed"], m["config"]["dataset_params"]["segment"]) == (3, 1, "0.6:1")
    from replay.data import dataset_ref
    from replay.tune.tuned import tuned_data

    run = {"runs": 10, "seed": 0, "alignment": "se3", "divergence_threshold": None}
    params, first, got, note = tuned_data(tuned / "tuned.toml", dataset_ref.resolve("sim/linear"), {"steps": 9}, 7,
                                          run, set())
    assert (params, first, got) == ({"steps": 9}, 7, run)  # another dataset: as given, and said
    assert note.endswith("tested on sim/lake-depth (rate=4.0, segment=0.6:1); sim/linear is evaluated as given "
                         "(only its filter and task parameters)"), note


def _row(label, train, test, **extra):
    return {"label": label, "filter": label.split()[0], "train_score": train, "test_score": test, **extra}


def test_board_notes_say_when_tuning_made_every_filter_worse_and_name_the_better_rows():
    from replay.tune.write import board_notes

    rows = [_row("ekf (default)", 3.9, 3.71), _row("ekf (tuned)", 2.1, 6.33), _row("pf (default)", 5.0, 4.0),
            _row("pf (tuned)", 4.0, 4.5), _row("measurements (raw observations)", "", 2.4)]
    assert board_notes(rows) == [
        "ekf: tuning made it worse on the held-out data (test 6.3300 against 3.7100 for the defaults; training "
        "2.1000 against 3.9000): the better row is ekf (default)",
        "pf: tuning made it worse on the held-out data (test 4.5000 against 4.0000 for the defaults; training "
        "4.0000 against 5.0000): the better row is pf (default)",
        "every tuned filter is worse on the held-out data than its defaults: the better rows are ekf (default), "
        "pf (default) (the tuned.toml written holds the tuned settings all the same)",
    ]
    rows[3]["test_score"] = 3.9  # pf improved: only ekf is named, no line about every filter
    assert len(board_notes(rows)) == 1 and board_notes(rows)[0].startswith("ekf: tuning made it worse")
    rows[1]["test_score"] = 3.0
    assert board_notes(rows) == []


def test_board_notes_explain_failed_trials_and_mark_rows_that_never_move():
    from replay.tune.write import board_notes, format_board

    rows = [_row("ekf (default)", 82.963, 82.963, still=True), _row("ekf (tuned)", 82.963, 82.963, still=True)]
    notes = board_notes(rows, {"pf": ["2 of 2 runs diverged (a setting with a diverged run is not usable)"] * 2})
    assert notes == [
        "ekf (default): not ranked: never moves: every estimate stays at its start, so its error is the start's, "
        "not a filter's",
        "ekf (tuned): not ranked: never moves: every estimate stays at its start, so its error is the start's, "
        "not a filter's",
        "pf: 2 trial(s) failed (the progress line's 'failed'), scored infinity: 2 of 2 runs diverged (a setting "
        "with a diverged run is not usable) (2x)",
    ]
    for r in rows:
        r.update(tuned_on="x", objective="mean_rmse", trials=0, pos_rmse=82.963, lost=0, runs=2)
    assert "ekf (tuned) (not ranked)" in format_board(rows)


def test_why_a_trial_scores_infinity():
    from replay.scoring.record import RunRecord
    from replay.tune.objectives import value, why_inf

    ok = RunRecord(0, "done", {"diverged": False, "pos_rmse": 1.0})
    div = RunRecord(1, "done", {"diverged": True, "pos_rmse": 9.0})
    bad = RunRecord(1, "failed", error="MemoryError")
    w = {"mean_rmse": 1.0}
    assert value(w, [ok, ok]) == 1.0 and why_inf(w, [ok, ok]) == ""
    assert value(w, [ok, div]) == float("inf")
    assert why_inf(w, [ok, div]) == "1 of 2 runs diverged (a setting with a diverged run is not usable)"
    assert why_inf(w, [ok, bad]) == "1 of 2 runs failed (MemoryError)"
    assert why_inf({"nll": 1.0}, [ok]) == "objective nll not finite (e.g. no likelihood or NEES)"


def test_eval_tuned_with_a_fault_stresses_the_clean_tune_on_its_test_data(tuned, tmp_path):
    # issue 38 item 4: the configuration tuned on clean data, stressed by a fault on its own test data
    res = _eval(tmp_path, "f", "--tuned", str(tuned / "tuned.toml"), "--fault", "depth:bias:b=2,t0=10")
    assert res.exit_code == 0, res.output
    m = _results(tmp_path / "f")
    params = m["config"]["dataset_params"]
    assert params["rate"] == 4.0 and params["segment"] == "0.6:1" and params["fault"] == ["depth:bias:b=[2],t0=10"]
    res = _eval(tmp_path, "c", "--tuned", str(tuned / "tuned.toml"))
    assert res.exit_code == 0, res.output
    assert m["results"]["ekf"]["pos_rmse"] != _results(tmp_path / "c")["results"]["ekf"]["pos_rmse"]
