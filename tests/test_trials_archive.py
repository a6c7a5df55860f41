"""``replay score --trials`` (aggregation equal to a hand computation), ``--save-results`` and ``replay res``
(the archive read back to full precision), ``replay.score(..., trials=)``."""
from __future__ import annotations

import csv
import json
import math

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import replay
from replay.cli.main import main
from replay.trajectory.base import make
from replay.trajectory.files import write_tum

T975_2 = 4.302652729749462  # Student t, 0.975 quantile, 2 degrees of freedom (scipy.stats.t.ppf(0.975, 2))


def run(*args):
    return CliRunner().invoke(main, list(map(str, args)), catch_exceptions=False)


@pytest.fixture
def line(tmp_path):
    """A 100 m straight line (1 m steps) and 3 trials with scale errors of 1, 2, 3 %."""
    n = 101
    t = 10.0 + np.arange(n) * 0.1
    p = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)])
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    write_tum(tmp_path / "gt.tum", make(t, p, q, source="gt"))
    (tmp_path / "runs").mkdir()
    for k in (1, 2, 3):
        write_tum(tmp_path / "runs" / f"est_run{k}.txt", make(t, p * (1 + 0.01 * k), q, source="est"))
    return tmp_path


def _hand(values):
    v = np.asarray(values, float)
    return v.mean(), float(np.median(v)), T975_2 * v.std(ddof=1) / math.sqrt(len(v))


def _agrees(trials, agg, column, values):
    """Each trial's ``column`` equals ``values``; the aggregated row their mean, median and 95 % t half-width."""
    for row, want in zip(trials, values):
        assert float(row[column]) == pytest.approx(want, rel=1e-12)
    for suffix, want in zip(("", "_median", "_ci95"), _hand(values)):
        assert float(agg[column + suffix]) == pytest.approx(want, rel=1e-12), suffix


def test_trials_aggregate_equals_hand_computation(line):
    out = line / "lb.csv"
    r = run("score", line / "gt.tum", "--trials", f"est={line}/runs/est_run*.txt", "--lengths", "10",
            "--lengths-method", "kitti", "--lost-threshold", 1.5, "--rpe", "-o", out)
    assert r.exit_code == 0, r.output
    assert "trials of est: 3; lost 2/3" in r.output
    rows = list(csv.DictReader(out.open()))
    trials = [row for row in rows if row["trial"] != ""]
    (agg,) = [row for row in rows if row["trial"] == ""]
    assert [row["trial"] for row in trials] == ["1", "2", "3"]
    assert [row["trial_source"].rsplit("/", 1)[-1] for row in trials] == ["est_run1.txt", "est_run2.txt",
                                                                          "est_run3.txt"]
    # APE: error 0.01 k x, mean of x^2 over 0..100 = 3350
    _agrees(trials, agg, "ape_trans_rmse", [0.01 * k * math.sqrt(3350.0) for k in (1, 2, 3)])
    # KITTI sub-trajectories of 10 m on 1 m steps end 11 m on: trans_perc = k % * 11 / 10 in every sample
    _agrees(trials, agg, "rel_trans_perc_rmse", [1.1 * k for k in (1, 2, 3)])
    # lost: error above 1.5 m for 10 matched poses: trials 2 (from x = 76) and 3 (x = 51), not 1 (1 m at most)
    assert [row["lost"] for row in trials] == ["0", "1", "1"] and agg["lost"] == "2" and agg["runs"] == "3"
    assert agg["filter"] == "recorded:est" and json.loads(agg["params"])["trials"][2].endswith("est_run3.txt")


def test_trials_from_python_equal_the_cli(line):
    res = replay.score(str(line / "gt.tum"), trials={"est": str(line / "runs" / "est_run*.txt")}, rpe=True)
    df = res.trials()
    agg = df[df["trial"] == ""].iloc[0]
    mean, median, ci = _hand([0.01 * k * math.sqrt(3350.0) for k in (1, 2, 3)])
    assert agg["ape_trans_rmse"] == pytest.approx(mean, rel=1e-12)
    assert agg["ape_trans_rmse_ci95"] == pytest.approx(ci, rel=1e-12)
    assert list(res.scores) == ["est/1", "est/2", "est/3"]
    lb = res.leaderboard()
    assert list(lb["trial"]) == [1, 2, 3, ""] and lb["runs"].tolist() == [1, 1, 1, 3]
    # a list is one trial set; natural order of the glob (run10 after run2) is kept for given lists as given
    res2 = replay.score(str(line / "gt.tum"), trials=[str(line / "runs" / f"est_run{k}.txt") for k in (3, 1, 2)])
    assert [s.split("/")[-1] for s in res2.trials()["trial_source"][:3]] == ["est_run3.txt", "est_run1.txt",
                                                                          "est_run2.txt"]


def test_glob_in_natural_order(tmp_path):
    from replay.trajectory.trials import parse

    for k in (1, 2, 10):
        (tmp_path / f"r{k}.txt").write_text("")
    sets = parse([f"{tmp_path}/r*.txt"])
    assert list(sets) == ["r"] and [s.rsplit("/", 1)[-1] for s in sets["r"]] == ["r1.txt", "r2.txt", "r10.txt"]


@pytest.fixture
def saved(tmp_path):
    """Two estimates of a curved track (scale errors 1 % and 3 %, noise), scored and saved."""
    rng = np.random.default_rng(1)
    n = 101
    t = 10.0 + np.arange(n) * 0.1
    s = np.arange(n, dtype=float)
    p = np.column_stack([s, 5 * np.sin(s / 10), np.zeros(n)])
    yaw = np.arctan2(0.5 * np.cos(s / 10), 1.0)
    q = np.column_stack([np.zeros(n), np.zeros(n), np.sin(yaw / 2), np.cos(yaw / 2)])
    line = tmp_path / "in"
    (line / "runs").mkdir(parents=True)
    write_tum(line / "gt.tum", make(t, p, q, source="gt"))
    for k in (1, 3):
        write_tum(line / "runs" / f"est_run{k}.txt",
                  make(t, p * (1 + 0.01 * k) + rng.normal(0, 0.01, (n, 3)), q, source="est"))
    res = replay.score(str(line / "gt.tum"), [str(line / "runs" / "est_run1.txt"), str(line / "runs" /
                                                                                         "est_run3.txt")],
                       align="sim3", rpe=True, delta=5, delta_unit="m", pose_relation=["trans", "angle_deg"],
                       lengths="10,20")
    out = tmp_path / "archive"
    r = run("score", line / "gt.tum", line / "runs" / "est_run1.txt", line / "runs" / "est_run3.txt", "-as",
            "--rpe", "-d", 5, "-u", "m", "-r", "trans", "-r", "angle_deg", "--lengths", "10,20",
            "--save-results", out)
    assert r.exit_code == 0, r.output
    return res, out


def test_archive_round_trip_to_full_precision(saved, tmp_path):
    res, out = saved
    table = tmp_path / "t.csv"
    r = run("res", out, "-o", table)
    assert r.exit_code == 0, r.output
    got = pd.read_csv(table, keep_default_na=False)
    want = res.stats()
    plain = got[got["metric"] != "rel"].reset_index(drop=True)
    assert len(plain) == len(want) == 8
    for k in ("rmse", "mean", "median", "std", "min", "max", "sse"):
        assert [float(x) for x in plain[k]] == want[k].tolist(), k  # every digit
    assert plain["n"].tolist() == want["n"].tolist()
    rel = got[got["metric"] == "rel"]
    lengths = res.lengths()
    for _, row in lengths.iterrows():
        hit = rel[(rel["estimate"] == row["filter"][9:]) & (rel["length"] == row["length"])
                  & (rel["relation"] == "trans_perc")]
        assert float(hit["rmse"].iloc[0]) == row["rel_trans_perc_rmse"]
    meta = json.loads((out / "results.json").read_text())
    R, t, c = res["est_run3"].transform
    tr = meta["estimates"][1]["transform"]
    assert np.array_equal(np.array(tr["R"]), R) and np.array_equal(np.array(tr["t"]), t) and tr["scale"] == c
    assert c == pytest.approx(1 / 1.03, rel=1e-3)
    ape = pd.read_parquet(out / "ape.parquet")
    pd.testing.assert_frame_equal(ape.drop(columns=["ref_x", "ref_y", "ref_z"]), res.errors("ape"), check_exact=True)
    assert np.array_equal(ape["ref_x"].to_numpy()[:101], np.arange(101.0))
    assert res.stats().query("metric == 'ape'")["rmse"].min() > 1e-3  # the numbers compared are not zeros
    rpe = pd.read_parquet(out / "rpe.parquet")
    pd.testing.assert_frame_equal(rpe.drop(columns=["i", "j"]), res.errors("rpe"), check_exact=True)
    first = ape[ape["estimate"] == "est_run1"]
    pairs = rpe[rpe["estimate"] == "est_run1"]
    assert np.array_equal(first["t"].to_numpy()[pairs["i"]], pairs["t_i"]) and pairs["j"].gt(pairs["i"]).all()
    assert meta["settings"]["align"] == "sim3" and len(meta["config_hash"]) == 16


def test_res_markdown_latex_and_plot(saved, tmp_path):
    _, out = saved
    md = run("res", out, "--digits", 4)
    assert md.exit_code == 0 and md.output.startswith("| results | estimate |"), md.output
    tex = tmp_path / "t.tex"
    r = run("res", out, out, "-o", tex)
    text = tex.read_text()
    assert r.exit_code == 0 and text.startswith("\\begin{tabular}") and "trans\\_perc" in text
    assert text.count("est\\_run1") == 2 * text.count("est\\_run3") // 2 and "\\end{tabular}" in text


@pytest.mark.slow  # matplotlib: about 2 s
def test_res_plot_and_trials_plot(line, saved, tmp_path):
    _, out = saved
    png = tmp_path / "p.png"
    r = run("res", out, "--plot", png)
    assert r.exit_code == 0 and png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 20_000, r.output
    box = tmp_path / "b.png"
    r = run("score", line / "gt.tum", "--trials", f"{line}/runs/est_run*.txt", "--lengths", "10", "--trials-plot", box)
    assert r.exit_code == 0 and box.read_bytes()[:4] == b"\x89PNG", r.output


def test_trials_archive_table(line, tmp_path):
    out = tmp_path / "a"
    r = run("score", line / "gt.tum", "--trials", f"{line}/runs/est_run*.txt", "--save-results", out)
    assert r.exit_code == 0, r.output
    r = run("res", out, "--table", "trials", "--format", "csv")
    rows = list(csv.DictReader(r.output.splitlines()))
    ape = next(row for row in rows if row["metric"] == "ape_trans_rmse")
    mean, median, ci = _hand([0.01 * k * math.sqrt(3350.0) for k in (1, 2, 3)])
    assert ape["estimate"] == "est_run" and ape["trials"] == "3"
    assert float(ape["mean"]) == pytest.approx(mean, rel=1e-12) and float(ape["ci95"]) == pytest.approx(ci, rel=1e-12)


def test_save_replaces_an_archive_whole(saved, tmp_path):
    res, out = saved
    res2 = replay.score(str(tmp_path / "in" / "gt.tum"), str(tmp_path / "in" / "runs" / "est_run3.txt"))
    res2.save(out)
    meta = json.loads((out / "results.json").read_text())
    assert [e["name"] for e in meta["estimates"]] == ["est_run3"] and not (out / "rpe.parquet").exists()


def test_res_aggregates_recorded_estimates_across_eval_outputs(tmp_path):
    """Three ``replay eval`` outputs of three recordings, each with a recorded:orb row: one trial each."""
    from replay.scoring.summary import columns
    from replay.util.files import write_csv
    from replay.util.staging import MARKER

    dirs = []
    for k, (rmse, ate) in enumerate(((1.0, 0.5), (2.0, 0.25), (4.5, 0.75))):
        d = tmp_path / f"run{k}"
        d.mkdir()
        rows = [{"dataset": f"rec{k}.bag", "task": "recorded", "filter": "recorded:orb", "label": "recorded:orb",
                 "params": "{}", "runs": 1, "diverged": 0, "lost": "", "failed": 0, "pos_rmse": rmse, "ate": ate,
                 "scored": 100, "masked": 0},
                {"dataset": f"rec{k}.bag", "task": "recorded", "filter": "ekf", "label": "ekf", "params": "{}",
                 "runs": 1, "diverged": 0, "lost": "", "failed": 0, "pos_rmse": 9.0, "scored": 100, "masked": 0}]
        write_csv(rows, d / "leaderboard.csv", columns(rows))
        (d / MARKER).write_text(json.dumps({"tool": "replay", "kind": "replay eval", "files": ["leaderboard.csv"]}))
        dirs.append(d)
    r = run("res", *dirs, "--table", "trials", "--format", "csv")
    assert r.exit_code == 0, r.output
    got = {row["metric"]: row for row in csv.DictReader(r.output.splitlines())}
    assert set(got) == {"pos_rmse", "ate"} and got["pos_rmse"]["estimate"] == "orb" and got["ate"]["trials"] == "3"
    for metric, values in (("pos_rmse", (1.0, 2.0, 4.5)), ("ate", (0.5, 0.25, 0.75))):
        mean, median, ci = _hand(values)
        assert float(got[metric]["mean"]) == pytest.approx(mean, rel=1e-14)
        assert float(got[metric]["median"]) == median and float(got[metric]["ci95"]) == pytest.approx(ci, rel=1e-12)
    r = CliRunner().invoke(main, ["res", str(dirs[0])])
    assert r.exit_code == 2 and "a replay eval or campaign output" in r.output and len(r.output.splitlines()) == 1
