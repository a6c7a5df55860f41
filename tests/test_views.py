"""Views of a dataset (``rate``, ``window``, ``segment``: replay/data/views.py) and the splits of replay/data/splits.py."""
import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

from replay.data import registry, views
from replay.cli import main
from replay.frame import Channel, Frame, RecordedEstimate
from replay.data.splits import check_disjoint, split_views
from replay.util.errors import ReplayError


def _frame(t, valid=None, epoch=None):
    t = np.asarray(t, float)
    x = Channel(10 * t + 1, "m", valid=valid)
    yaw = Channel(np.where(np.arange(len(t)) % 2, 3.1, -3.1), "rad", angles=(0,))
    ref = Channel(np.column_stack([t, -t]), "m", components=("east", "north"))
    return Frame(t, {"x": x, "yaw": yaw}, {"position": ref}, epoch, {"source": "test"})


# ---------------------------------------------------------------- rate

def test_rate_takes_the_nearest_valid_sample_within_half_a_period():
    # grid 0, 1, 2, 3 (1 Hz); half-periods [-0.5, 0.5), [0.5, 1.5), [1.5, 2.5), [2.5, 3.5)
    f = _frame([0.0, 0.3, 0.45, 0.55, 1.0, 1.25, 2.75, 3.25])
    out = views.apply(f, {"rate": 1})
    np.testing.assert_array_equal(out.t, [0, 1, 2, 3])
    x = out.channels["x"]
    np.testing.assert_array_equal(x.valid, [True, True, False, True])
    np.testing.assert_array_equal(x.values[x.valid], [1.0, 11.0, 28.5])  # t = 0, 1.0, and 2.75 (tie: the earlier)
    assert np.isnan(x.values[2])  # nothing in [1.5, 2.5): masked, not invented
    ref = out.reference["position"]
    np.testing.assert_array_equal(ref.values[ref.valid][:, 0], [0.0, 1.0, 2.75])
    dropped = {e.what: e.count for e in out.report.find("dropped")}
    masked = {e.what: e.count for e in out.report.find("masked")}
    assert dropped == {"x": 5, "yaw": 5, "position": 5} and masked == {"x": 1, "yaw": 1, "position": 1}
    assert out.meta["view"] == {"rate": 1.0, "offset_s": 0.0, "samples": [0, 8], "of": 8, "grid": 4}
    assert f.report.entries == [] and len(f.t) == 8  # the input frame untouched


def test_half_period_rule_a_sample_on_the_boundary_belongs_to_the_later_point():
    out = views.apply(_frame([0.0, 1.5]), {"rate": 1})
    np.testing.assert_array_equal(out.t, [0, 1, 2])
    np.testing.assert_array_equal(out.channels["x"].valid, [True, False, True])
    assert out.channels["x"].values[2] == 16.0  # the sample at 1.5, taken once


def test_an_invalid_sample_is_never_taken():
    f = _frame([0.0, 0.1, 0.9, 1.2], valid=[False, True, False, True])
    x = views.apply(f, {"rate": 1}).channels["x"]
    np.testing.assert_array_equal(x.values, [2.0, 13.0])  # t = 0.1 (not the invalid t = 0), t = 1.2


def test_no_sample_is_invented_averaged_or_taken_twice():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 0.4, 400))
    f = _frame(t - t[0], valid=rng.random(400) > 0.3)
    for rate in (0.7, 1.0, 3.3, 20.0):
        out = views.apply(f, {"rate": rate})
        for name, ch in {"x": out.channels["x"], "position": out.reference["position"]}.items():
            src = f.channels.get(name) or f.reference[name]
            vals = src.values.reshape(len(src), -1)
            taken = ch.values.reshape(len(ch), -1)[ch.valid]
            rows = [int(np.flatnonzero((vals == v).all(axis=1) & src.valid)[0]) for v in taken]
            assert len(set(rows)) == len(rows)  # each original sample at most once
            shift = np.abs(f.t[rows] - out.t[ch.valid])
            assert np.all(shift <= 0.5 / rate + 1e-12)
        yaw = out.channels["yaw"]
        assert set(np.round(yaw.values[yaw.valid], 12)) <= {3.1, -3.1}  # angles are samples, never averaged


def test_bohai_like_ten_hertz_at_one_hertz():
    t = np.arange(0, 126.0, 0.102)  # ~9.8 Hz as the Bohai CSVs: 1236 samples over 126 s
    out = views.apply(_frame(t), {"rate": 1})
    assert len(out.t) == 127 and out.channels["x"].valid.all()
    assert out.report.find("dropped", "x")[0].count == len(t) - 127


# ---------------------------------------------------------------- window and segment

def test_window_in_seconds_and_indices_rebases_time_and_keeps_the_offset():
    f = _frame(np.arange(10.0), epoch=1000.0)
    f.estimates["ins"] = RecordedEstimate(np.arange(10.0) + 0.5, np.zeros((10, 3)))
    out = views.apply(f, {"window": "3:7"})
    np.testing.assert_array_equal(out.t, [0, 1, 2, 3])  # samples 3, 4, 5, 6 (END excluded)
    np.testing.assert_array_equal(out.channels["x"].values, [31, 41, 51, 61])
    assert out.epoch == 1003.0 and out.meta["view"]["offset_s"] == 3.0 and out.meta["view"]["samples"] == [3, 7]
    np.testing.assert_array_equal(out.estimates["ins"].t, [0.5, 1.5, 2.5])
    assert out.report.find("dropped", "samples")[0].count == 6
    by_index = views.apply(f, {"window": "#3:7"})
    np.testing.assert_array_equal(by_index.channels["x"].values, out.channels["x"].values)
    np.testing.assert_array_equal(views.apply(f, {"window": "7:"}).channels["x"].values, [71, 81, 91])
    np.testing.assert_array_equal(views.apply(f, {"window": ":2"}).t, [0, 1])


def test_segments_split_the_duration_without_a_shared_sample():
    f = _frame(np.arange(11.0))  # duration 10 s
    a, b = views.apply(f, {"segment": "0:0.6"}), views.apply(f, {"segment": "0.6:1"})
    np.testing.assert_array_equal(a.channels["x"].values, 10 * np.arange(6.0) + 1)  # t < 6
    np.testing.assert_array_equal(b.channels["x"].values, 10 * np.arange(6.0, 11.0) + 1)  # t >= 6, the last kept
    both = views.apply(f, {"window": "2:", "segment": "0:0.5", "rate": 0.5})  # window, segment of it, then rate
    assert both.meta["view"]["offset_s"] == 2.0 and both.meta["view"]["samples"] == [2, 6]
    np.testing.assert_array_equal(both.channels["x"].values, [21, 41, 51])  # samples at 2, 4, 5 s (grid 0, 2, 4)


@pytest.mark.parametrize("params, message", [
    ({"rate": 0}, "rate must be a finite number > 0"),
    ({"rate": -1}, "rate must be a finite number > 0"),
    ({"rate": "fast"}, "rate must be"),
    ({"window": "abc"}, "window must be START:END"),
    ({"window": "60:30"}, "window '60:30': the end must be after the start"),
    ({"window": "#1.5:9"}, "sample indices after '#' must be whole numbers"),
    ({"window": "-5:9"}, "window must be START:END"),
    ({"segment": "0.6:0.2"}, "segment must be A:B with 0 <= A < B <= 1"),
    ({"segment": "0:1.5"}, "segment must be A:B"),
    ({"segment": ":"}, "segment .:. keeps everything"),
    ({"segment": 0.6}, "segment must be a string"),
])
def test_bad_views_are_refused_in_one_line_naming_the_parameter(params, message):
    for dataset in ("sim/ungm", "bohai/20220822_0_6", "log.csv"):
        with pytest.raises(ReplayError, match=message.replace("(", r"\(")) as err:
            registry.check_params(dataset, params)
        assert "\n" not in str(err.value)


def test_an_empty_view_names_the_window_and_the_recording():
    with pytest.raises(ReplayError, match=r"test: the window 500:600 holds no sample of the 9 s recording"):
        views.apply(_frame(np.arange(10.0)), {"window": "500:600"}, "test")


def test_views_are_canonical_and_absent_views_leave_the_parameters_as_before():
    assert registry.check_params("sim/ungm", {}) == registry.check_params("sim/ungm", {"rate": None})
    assert "rate" not in registry.check_params("sim/ungm", {})
    got = registry.check_params("sim/ungm", {"rate": 1, "window": "60.0:", "segment": ":0.50"})
    assert (got["rate"], got["window"], got["segment"]) == (1.0, "60:", "0:0.5")


def test_a_view_that_cuts_the_start_of_a_simulation_is_refused():
    with pytest.raises(ReplayError, match="sim/ungm: window 10: starts 10 s after the first sample"):
        registry.load_frame("sim/ungm", rng=0, window="10:")
    assert len(registry.load_frame("sim/ungm", rng=0, window=":50")) == 50  # its end may be cut


# ---------------------------------------------------------------- eval, campaign, rerun

def _rows(path):
    with open(path, newline="") as fh:
        return {r["filter"]: {k: v for k, v in r.items() if k not in ("us_per_step", "version")}
                for r in csv.DictReader(fh)}


def test_eval_and_campaign_give_the_same_rows_with_a_view_and_rerun_repeats_it(tmp_path):
    runner = CliRunner()
    res = runner.invoke(main, ["eval", "sim/lake-depth", "--filters", "ekf", "--runs", "2", "--rate", "4",
                               "--window", "10:70", "--out", str(tmp_path / "eval"), "-q"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    manifest = json.loads((tmp_path / "eval" / "manifest.json").read_text())
    assert manifest["config"]["dataset_params"]["rate"] == 4.0
    assert manifest["dataset"]["view"]["grid"] == 241 and manifest["dataset"]["view"]["offset_s"] == 10.0
    (tmp_path / "c.toml").write_text('[campaign]\nname = "v"\nruns = 2\nseed = 0\n\n[[dataset]]\n'
                                     'id = "sim/lake-depth"\ntasks = ["depth"]\n'
                                     'params = { rate = 4, window = "10:70" }\n\n[[filter]]\nname = "ekf"\n')
    res = runner.invoke(main, ["campaign", "run", str(tmp_path / "c.toml"), "-o", str(tmp_path / "camp"), "-w", "1",
                               "-q"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    ev, cp = _rows(tmp_path / "eval" / "leaderboard.csv"), _rows(tmp_path / "camp" / "leaderboard.csv")
    assert {k: ev["ekf"][k] for k in cp["ekf"]} == cp["ekf"] and float(ev["ekf"]["depth_rmse"]) > 0
    assert cp["ekf"]["config_hash"] == ev["ekf"]["config_hash"]  # the view is in the hash of both
    assert ev["ekf"]["view"] == "rate=4 window=10:70"
    res = runner.invoke(main, ["rerun", str(tmp_path / "eval" / "manifest.json"), "-q"], catch_exceptions=False)
    assert res.exit_code == 0 and "reproduced" in res.output, res.output
    # without the view the numbers differ: the view is what was repeated
    res = runner.invoke(main, ["eval", "sim/lake-depth", "--filters", "ekf", "--runs", "2", "--out",
                               str(tmp_path / "plain"), "-q"], catch_exceptions=False)
    assert _rows(tmp_path / "plain" / "leaderboard.csv")["ekf"]["depth_rmse"] != ev["ekf"]["depth_rmse"]


def test_cli_refuses_a_view_given_twice_and_a_bad_rate(tmp_path):
    runner = CliRunner()
    res = runner.invoke(main, ["eval", "sim/lake-depth", "--rate", "1", "--dataset-param", "rate=2"])
    assert res.exit_code == 2 and "give the view once" in res.output
    res = runner.invoke(main, ["eval", "sim/lake-depth", "--rate", "0"])
    assert res.exit_code == 2 and "rate must be a finite number > 0" in res.output
    assert "Traceback" not in res.output


def test_bohai_position_at_one_hertz(bohai_dir, tmp_path):
    frame = registry.load_frame("bohai/20220822_0_6", data_dir=bohai_dir, rate=1)
    assert len(frame) == 952 and frame.meta["view"]["of"] == 7509  # 950.5 s at ~9.8 Hz -> one sample per second
    ref = frame.reference["position"]
    assert int(ref.valid.sum()) == 691 and frame.report.find("masked", "position")[-1].count == 261
    res = CliRunner().invoke(main, ["eval", "bohai/20220822_0_6", "--data-dir", str(bohai_dir), "--task",
                                    "position", "--rate", "1", "--filters", "ekf,ukf,ckf", "--out",
                                    str(tmp_path / "b"), "-q"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    rows = _rows(tmp_path / "b" / "leaderboard.csv")
    assert float(rows["ekf"]["pos_rmse"]) == pytest.approx(3.1805, abs=5e-4)
    assert float(rows["measurements"]["pos_rmse"]) == pytest.approx(2.4609, abs=5e-4)


# ---------------------------------------------------------------- splits

def test_split_views():
    assert split_views({"segment": 0.6}) == ({"segment": "0:0.6"}, {"segment": "0.6:1"})
    train, test = split_views({"train": ["bohai/20220822_0_3", "bohai/20220822_0_4"],
                               "test": ["bohai/20220822_0_5", "bohai/20220822_0_6"]})
    assert train == {"datasets": ["bohai/20220822_0_3", "bohai/20220822_0_4"]} and len(test["datasets"]) == 2
    assert split_views({"seeds": 3}) == ({"seed": 3}, {"seed": 4})
    assert split_views({"seeds": [5, 1]}) == ({"seed": 5}, {"seed": 1})


@pytest.mark.parametrize("spec, message", [
    ({"segment": 1.0}, "segment must be the training share"),
    ({"segment": 0.5, "seeds": 1}, "give exactly one of"),
    ({"train": ["a"], "test": []}, "test must be a non-empty list"),
    ({"train": ["a", "b"], "test": ["b"]}, "overlap: b in both"),
    ({"seeds": [2, 2]}, "overlap: both use master seed 2"),
    ({"seeds": -1}, "seeds must be"),
])
def test_bad_splits_are_refused(spec, message):
    with pytest.raises(ReplayError, match=message):
        split_views(spec)


def test_check_disjoint():
    assert check_disjoint({"segment": "0:0.6"}, {"segment": "0.6:1"}, dataset="d") is None
    assert check_disjoint({"window": "0:60", "rate": 1}, {"window": "60:", "rate": 1}) is None
    with pytest.raises(ReplayError, match=r"overlap: d in both \(segment 0:0.6 and segment 0.5:1\)"):
        check_disjoint({"segment": "0:0.6"}, {"segment": "0.5:1"}, dataset="d")
    assert "in both" in check_disjoint({"datasets": ["a"]}, {"datasets": ["a"]}, allow_overlap=True)
    with pytest.raises(ReplayError, match="overlap"):  # a window and a segment of one log: not provably apart
        check_disjoint({"window": "0:10"}, {"segment": "0.9:1"})


def test_a_seed_split_of_a_recording_is_an_overlap():
    assert check_disjoint({"seed": 1}, {"seed": 2}, dataset="sim/ungm") is None
    with pytest.raises(ReplayError, match="bohai/20220822_0_6 is a recording: its samples are the same"):
        check_disjoint({"seed": 1}, {"seed": 2}, dataset="bohai/20220822_0_6")
