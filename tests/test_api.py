"""The Python API (``import replay``; docs/python.md): DataFrame views, plots, campaigns, exports.

The tests at the end (section "methods") call ``Frame.to_pandas`` and ``Evaluation.leaderboard``
/ ``.estimates`` / ``.errors`` / ``.plot_errors``: one-line methods over :mod:`replay.run.tables`,
:mod:`replay.run.plots` and :mod:`replay.util.dataframes`.
"""
import csv
import gzip
import inspect
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import replay
from replay.run import tables
from replay.frame import Channel, Frame, Report
from replay.util.errors import ReplayError
from replay.util.files import fmt

SONAR = dict(dataset_params={"steps": 40}, runs=3, seed=4)
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def ev():
    return replay.evaluate("sim/auv-sonar", filters="ekf,ukf,ckf", **SONAR)


@pytest.fixture(scope="module")
def written(ev, tmp_path_factory):
    from replay.outputs.files import write_all

    out = tmp_path_factory.mktemp("eval") / "o"
    write_all(ev, out)
    return out


# ---------------------------------------------------------------- the package's API

def test_public_api_is_keyword_only_after_the_subject():
    for name in replay.__all__:
        func = getattr(replay, name)
        params = list(inspect.signature(func).parameters.values())
        loose = [p.name for p in params[1:] if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
        if name in ("score", "export_mcap"):
            loose = loose[1:]  # score(reference, estimate, ...), export_mcap(evaluation, path, ...)
        assert not loose, (name, loose)


def test_evaluate_and_score_are_plain_functions_beside_their_modules():
    import types

    import replay.run.evaluation as module
    import replay.scoring.scorer  # noqa: F401  (loading the submodules must not shadow the functions)

    assert module.Evaluation.__name__ == "Evaluation"
    for name in ("evaluate", "score"):
        assert isinstance(getattr(replay, name), types.FunctionType), name
    assert replay.evaluate is replay.api.evaluate and replay.score is replay.api.score
    assert "dataset" in inspect.signature(replay.evaluate).parameters
    from replay import evaluate, score

    from replay.scoring import scorer
    assert evaluate is replay.api.evaluate and score is replay.api.score and callable(scorer.score_run)
    import pkgutil

    assert not {m.name for m in pkgutil.iter_modules(replay.__path__)} & set(replay.__all__)  # would shadow
    from replay.trajectory import make

    t = np.arange(20.0)
    ref = make(t, np.column_stack([t, np.zeros(20), np.zeros(20)]), source="ref")
    est = make(t, np.column_stack([t + 0.5, np.zeros(20), np.zeros(20)]), source="est")
    assert replay.score(ref, est).stats()["rmse"].tolist() == pytest.approx([0.5], abs=1e-12)


def test_load_frame_seeded():
    a = replay.load_frame("sim/auv-sonar", seed=3, steps=30)
    b = replay.load_frame("sim/auv-sonar", seed=np.random.default_rng(3), steps=30)
    assert len(a) == 30 and np.array_equal(a.channels["sonar"].values, b.channels["sonar"].values)


# ---------------------------------------------------------------- DataFrames of an evaluation

def test_leaderboard_values_equal_the_csv(ev, written):
    df = tables.leaderboard(ev)
    with open(written / "leaderboard.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == list(df.columns) and len(rows) == len(df) + 1 == 4
    for i, cells in enumerate(rows[1:]):
        for col, text in zip(rows[0], cells):
            value = df.iloc[i][col]
            if text == "":
                assert value is None or pd.isna(value), (col, value)
            elif isinstance(value, (float, np.floating)):
                assert fmt(float(value)) == text and float(text) == pytest.approx(value, rel=5e-6, nan_ok=True)
            else:
                assert str(value) == text, (col, value, text)
    assert df.loc[1, "pos_rmse_vs_ekf"] == pytest.approx(ev.rows[1]["pos_rmse_vs_ekf"], rel=1e-15)
    assert np.isnan(df.loc[0, "pos_rmse_vs_ekf"])  # the baseline's own cell


def test_estimates_and_errors_equal_the_files(ev, written):
    est = tables.estimates(ev, "ukf")
    with gzip.open(written / "estimates" / "ukf.csv.gz", "rt") as fh:
        f = pd.read_csv(fh)
    assert est.index.names == ["run", "k"] and len(est) == len(f) == 3 * 40
    assert list(est.columns) == [c for c in f.columns if c not in ("run", "k") and not c.startswith("err_")]
    np.testing.assert_allclose(est.to_numpy(), f[est.columns].to_numpy(), rtol=1e-9)
    err = tables.errors(ev, "ukf")
    for axis in "xyz":
        np.testing.assert_allclose(err[f"err_{axis}"], f[f"err_{axis}"], rtol=1e-9, atol=1e-12)
    assert {"err", "err_pitch", "err_yaw"} <= set(err.columns)
    res = tables.result(ev, "ukf")
    for run in range(3):  # the per-run RMSE of the leaderboard, from the error table
        e = err.loc[run, "err"]
        assert np.sqrt(np.nanmean(e ** 2)) == pytest.approx(res.runs[run]["pos_rmse"], rel=1e-12)
    one = tables.estimates(ev, "ukf", run=2)
    assert one.index.name == "k" and np.array_equal(one.to_numpy(), est.loc[2].to_numpy())
    curve = np.loadtxt(written / "estimates" / "ukf_rmse_over_time.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(tables.rmse_over_time(ev)["ukf"], curve[:, 1], rtol=1e-9)
    with pytest.raises(ReplayError, match=r"^no filter 'pf' in this evaluation \(filters: ekf, ukf, ckf\)$"):
        tables.estimates(ev, "pf")


def test_run_metrics_and_paired(ev):
    runs = tables.run_metrics(ev)
    assert len(runs) == 9 and list(runs.columns[:3]) == ["filter", "run", "status"]
    for row in ev.rows:
        mine = runs[(runs["filter"] == row["filter"]) & ~runs["diverged"].astype(bool)]
        assert mine["pos_rmse"].mean() == pytest.approx(row["pos_rmse"], rel=1e-12)
    p = tables.paired(ev)
    ab = p[(p.a == "ekf") & (p.b == "ukf") & (p.metric == "pos_rmse")].iloc[0]
    assert ab["diff"] == pytest.approx(-ev.rows[1]["pos_rmse_vs_ekf"], rel=1e-12) and ab["n"] == 3


# ---------------------------------------------------------------- frames

def small_frame():
    t = np.array([0.0, 0.5, 1.0, 1.5])
    pos = Channel(np.arange(8.0).reshape(4, 2), "m", "ENU", valid=np.array([1, 1, 0, 1], bool),
                  components=("east", "north"))
    depth = Channel(np.array([1.0, 2.0, np.nan, 4.0]), "m", "down")
    raw = Channel(np.ones((4, 3)), "1", "", valid=np.array([0, 1, 1, 1], bool))
    ref = Channel(np.zeros((4, 2)), "m", "ENU", components=("east", "north"))
    report = Report()
    report.add("masked", "pos", 1, "a jump")
    return Frame(t, {"pos": pos, "depth": depth, "raw": raw}, {"position": ref}, 1.6e9, {"crs": "EPSG:32651"}, report)


def test_frame_table():
    from replay.util.dataframes import frame_table, report_table

    f = small_frame()
    df = replay.frame_table(f)
    assert list(df.columns) == ["pos.east", "pos.north", "depth", "raw.0", "raw.1", "raw.2"]
    assert df.index.name == "t" and df.index.tolist() == [0.0, 0.5, 1.0, 1.5]
    assert df["pos.east"].tolist()[:2] == [0.0, 2.0] and np.isnan(df.loc[1.0, "pos.north"])
    assert np.isnan(df.loc[0.0, "raw.1"]) and df.loc[0.5, "raw.1"] == 1.0
    assert df.attrs["units"]["depth"] == "m" and df.attrs["crs"] == "EPSG:32651"
    masked = frame_table(f, masks=True)
    assert masked.loc[1.0, "pos.east"] == 4.0 and masked["pos.valid"].tolist() == [True, True, False, True]
    ref = frame_table(f, reference=True)
    assert list(ref.columns) == ["position.east", "position.north"] and ref.attrs["group"] == "reference"
    utc = frame_table(f, time="utc")
    assert str(utc.index[2]) == "2020-09-13 12:26:41+00:00"
    assert report_table(f).to_dict("records") == [{"action": "masked", "what": "pos", "count": 1,
                                                   "reason": "a jump"}]


def test_bohai_frame_table_counts(bohai_dir):
    f = replay.load_frame("bohai/20220822_0_6", data_dir=bohai_dir)
    df = replay.frame_table(f)
    assert df["gps_position.east"].notna().sum() == f.channels["gps_position"].valid.sum() == 151
    assert len(df) == 7509 and "position.east" not in df  # the reference apart
    assert len(replay.report_table(f)) == len(f.report.entries)
    with pytest.raises(ReplayError, match="^time='utc': this frame has no epoch"):  # one line, not a ValueError
        replay.frame_table(f, time="utc")
    fig = replay.plot_track(f)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "UTM easting [m] (EPSG:32651)" and ax.get_ylabel() == "UTM northing [m] (EPSG:32651)"
    x = ax.lines[0].get_xdata()
    assert np.nanmin(x) == pytest.approx(f.meta["origin"][0] + np.nanmin(
        np.where(f.reference["position"].valid, f.reference["position"].values[:, 0], np.nan)))
    assert [line.get_label() for line in ax.lines] == ["reference", "GPS fixes"]


# ---------------------------------------------------------------- plots

def test_plots_have_units_and_the_numbers(ev, tmp_path):
    fig = replay.plot_errors(ev)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "time [s]" and ax.get_ylabel() == "position error, RMSE over 3 runs [m]"
    curves = tables.rmse_over_time(ev)
    assert [line.get_label() for line in ax.lines] == ["ekf", "ukf", "ckf"]
    np.testing.assert_array_equal(ax.lines[1].get_ydata(), curves["ukf"].to_numpy())
    bars = replay.plot_rmse(ev).axes[0]
    assert [b.get_height() for b in bars.patches] == [r["pos_rmse"] for r in ev.rows]
    assert bars.get_ylabel() == "pos_rmse [m]"
    paired = replay.plot_paired(ev).axes[0]
    assert paired.get_xlabel() == "pos_rmse minus ekf's, same runs [m]"
    assert paired.lines[0].get_xdata().tolist() == [r["pos_rmse_vs_ekf"] for r in ev.rows[1:]]
    track = replay.plot_track(ev, run=1).axes[0]
    assert track.get_xlabel() == "east [m] (local)" and len(track.lines) == 4
    np.testing.assert_array_equal(track.lines[0].get_xdata(), ev.truths[1][:, 0])  # every sample valid here
    np.testing.assert_array_equal(track.lines[2].get_ydata(), ev.results[1].estimates[1].x[:, 1])
    fig.savefig(tmp_path / "errors.png")
    assert (tmp_path / "errors.png").stat().st_size > 10_000


# ---------------------------------------------------------------- campaigns and exports

CAMPAIGN = """
[campaign]
name = "api"
runs = 2
seed = 1

[[dataset]]
id = "sim/auv-sonar"
tasks = ["sonar"]
params = { steps = 30 }

[[filter]]
name = "ekf"

[[filter]]
name = "ukf"
"""


def test_run_campaign_is_one_dataframe(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(CAMPAIGN)
    df = replay.run_campaign(path, out=tmp_path / "out", workers=1)
    assert df["filter"].tolist() == ["ekf", "ukf"] and df.attrs["counts"]["done"] == 4
    saved = pd.read_csv(tmp_path / "out" / "leaderboard.csv")
    assert list(saved.columns) == list(df.columns)
    np.testing.assert_allclose(saved["pos_rmse"], df["pos_rmse"], rtol=5e-6)
    again = replay.campaign_results(tmp_path / "out")
    assert again["pos_rmse"].tolist() == df["pos_rmse"].tolist()
    runs = replay.campaign_results(tmp_path / "out", runs=True)
    assert len(runs) == 4 and set(runs["run"]) == {0, 1}
    for name, group in runs.groupby("filter"):
        assert group["pos_rmse"].mean() == pytest.approx(df.set_index("filter").loc[name, "pos_rmse"], rel=1e-12)


def test_export_mcap(ev, tmp_path):
    path = tmp_path / "run.mcap"
    n = replay.export_mcap(ev, path, run=1)
    assert n > 3 * 40 and path.read_bytes()[:8] == b"\x89MCAP0\r\n"
    assert replay.export_mcap(ev, path, run=1) == n  # replay's own file is replaced
    other = tmp_path / "notes.mcap"
    other.write_text("mine")
    with pytest.raises(ReplayError):
        replay.export_mcap(ev, other)
    assert other.read_text() == "mine"


# ---------------------------------------------------------------- methods (one-line methods on Frame and Evaluation)

def test_methods_frame_to_pandas_and_evaluation_tables(ev):
    assert replay.frame_table(small_frame()).equals(small_frame().to_pandas())
    assert small_frame().to_pandas(reference=True).columns.tolist() == ["position.east", "position.north"]
    pd.testing.assert_frame_equal(ev.leaderboard(), tables.leaderboard(ev))
    pd.testing.assert_frame_equal(ev.estimates("ukf"), tables.estimates(ev, "ukf"))
    pd.testing.assert_frame_equal(ev.errors("ckf", run=0), tables.errors(ev, "ckf", run=0))
    assert ev.plot_errors().axes[0].get_xlabel() == "time [s]"


@pytest.mark.slow
def test_methods_python_c_leaderboard_equals_csv(tmp_path):
    """The issue's acceptance line, in a fresh interpreter."""
    code = ("import replay; ev = replay.evaluate('sim/auv-sonar', filters='ekf,ukf', runs=2, "
            "dataset_params={'steps': 30}); df = ev.leaderboard(); "
            "from replay.outputs.files import write_all; write_all(ev, 'o'); "
            "import pandas as pd; s = pd.read_csv('o/leaderboard.csv'); "
            "print(type(df).__name__, (abs(s['pos_rmse'] - df['pos_rmse']) <= 5e-6 * df['pos_rmse']).all())")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["DataFrame", "True"]
