"""``replay tune`` decides train/test overlap on content (sha256 and time spans), not names, and
refuses a part with too few samples (issue 33 item 5): one line, exit 2, before any trial."""
import numpy as np
import pytest
from click.testing import CliRunner

from replay.adapters.bohai import COLS36
from replay.cli import main
from replay.data import dataset_ref
from replay.tune import check, parts
from replay.tune.options import TuneOptions

KF = ["--filters", "kf", "--runs", "1", "--trials", "1", "--task", "position", "-p", "kf.q_scale=log[0.1,10]", "-q"]


def bohai(path, n=200, seed=0):
    """A small synthetic Bohai CSV: ``n`` rows at 1 Hz (t = 0..n-1 s from its first row), a straight track."""
    rng = np.random.default_rng(seed)
    rows = [",".join(COLS36)]
    for i in range(n):
        v = dict.fromkeys(COLS36, 0.0)
        lat, lon = 40.5 + 1e-5 * i, 121.0 + 1e-5 * i
        v.update(lat_gps=lat + 1e-6 * rng.standard_normal(), lon_gps=lon, lat=lat, lon=lon, time=1000.0 + i,
                 time_gps=1000.0 + i, numsats=10, navstat=4)
        rows.append(",".join(repr(float(v[c])) for c in COLS36))
    path.write_text("\n".join(rows) + "\n")
    return path


def refused(tmp_path, *args, match):
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["tune", *args, "--out", str(out)])
    line = res.output.strip()
    assert res.exit_code == 2, res.output
    assert line.startswith("replay: error: ") and "\n" not in line and "Traceback" not in line, line
    for m in [match] if isinstance(match, str) else match:
        assert m in line, line
    assert not out.exists()  # nothing computed, nothing written
    return line


def test_the_same_file_by_another_path_or_a_copy_overlaps(tmp_path):
    a = bohai(tmp_path / "a.csv")
    (tmp_path / "sub").mkdir()
    other_path = str(tmp_path / "sub" / ".." / "a.csv")
    copy = tmp_path / "b.csv"
    copy.write_bytes(a.read_bytes())
    link = tmp_path / "link.csv"
    link.symlink_to(a)
    for test in (other_path, str(copy), str(link)):
        line = refused(tmp_path, "--train", str(a), "--test", test, *KF,
                       match=["overlap", "are the same data (sha256", "both reading 0..199 s"])
        assert "--allow-overlap" in line
    refused(tmp_path, "--train", str(a), "--test", str(copy), "--window", "20:80", *KF,
            match="both reading 20..79 s")  # the same view of both: the same samples


def test_a_seed_split_of_a_recording_overlaps(tmp_path):
    a = bohai(tmp_path / "a.csv")
    refused(tmp_path, str(a), "--split", "seeds", *KF,
            match=["in both, both reading 0..199 s", "(a recording: its samples are the same under every seed)"])


def _part(path, view):
    ref = dataset_ref.resolve(str(path))
    return parts.read(str(path), view, seed=0, first=None, data_dir=None, ref=ref, where="test")


def test_two_views_of_one_content_overlap_iff_their_time_spans_intersect(tmp_path):
    a, b = bohai(tmp_path / "a.csv"), tmp_path / "b.csv"  # t = 0..199 s
    b.write_bytes(a.read_bytes())
    first_half = _part(a, {"segment": "0:0.5"})  # t < 99.5
    assert (first_half.lo, first_half.hi, first_half.n) == (0.0, 99.0, 100)
    second_half = _part(b, {"segment": "0.5:1"})
    assert (second_half.lo, second_half.hi, second_half.n) == (100.0, 199.0, 100)
    assert parts.overlap([("a", first_half)], [("b", second_half)]) is None
    assert parts.overlap([("a", _part(a, {"window": "0:100"}))], [("b", second_half)]) is None  # t < 100
    met = parts.overlap([("a", _part(a, {"window": "0:100.5"}))], [("b", second_half)])  # t = 100 in both
    assert met.startswith("a and b are the same data (sha256") and met.endswith("both reading 100..100 s")
    assert parts.overlap([("a", _part(a, {"segment": "0:0.6"}))], [("b", second_half)]).endswith("100..119 s")
    resampled = _part(a, {"segment": "0:0.5", "rate": 0.5})  # grid 0, 2, .., 100 s; samples of its cut only
    assert (resampled.lo, resampled.hi, resampled.n) == (0.0, 99.0, 51)
    assert parts.overlap([("a", resampled)], [("b", second_half)]) is None
    other = _part(bohai(tmp_path / "c.csv", seed=1), {})  # other content, the same times
    assert other.data != first_half.data and parts.overlap([("c", other)], [("b", second_half)]) is None


def _prepare(**kw):
    return check.prepare(TuneOptions(filters=["kf"], entries=[("kf.q_scale", "log[0.1,10]", "--param kf.q_scale")],
                                     trials=1, objective="mean_rmse", runs=1, seed=0, task="position", **kw))


def test_apart_segments_of_a_window_and_other_content_are_not_flagged(tmp_path):
    a, c = bohai(tmp_path / "a.csv"), bohai(tmp_path / "c.csv", seed=1)
    t = _prepare(dataset=str(a), train_segment="0.5", view={"window": "0:150"})  # flagged by name before
    assert t.split.overlap is None
    t = _prepare(dataset=str(a), train_segment="0.5", view={"rate": 0.5})  # the grids end at 100 s and start there
    assert t.split.overlap is None
    assert _prepare(dataset=None, train=str(a), test=str(c)).split.overlap is None
    allowed = _prepare(dataset=None, train=str(a), test=str(c) + "," + str(a), allow_overlap=True)
    assert allowed.split.overlap == f"{a} in both, both reading 0..199 s"


@pytest.mark.parametrize("args, match", [
    (["--train-segment", "1e-9"], ["--train-segment 1e-9: the training part", "holds 1 sample"]),
    (["--train-segment", "0.1"], ["--train-segment 0.1: the training part", "it holds 6 samples",
                                  "at least 10 (min_samples)"]),
    (["--train-segment", "0.95"], ["--train-segment 0.95: the test part", "it holds 3 samples"]),
    (["--split", "seeds", "--first", "9"], ["--split seeds: the training part", "it holds 9 samples"]),
])
def test_a_part_with_too_few_samples_is_refused_naming_the_option(tmp_path, args, match):
    refused(tmp_path, "sim/linear", "--filters", "kf", "--dataset-param", "steps=60", "--runs", "1", "--trials",
            "1", "-p", "task.q=log[0.1,10]", "-q", *args, match=match)
    assert parts.MIN_SAMPLES.default == 10


def test_a_registered_recording_and_a_copy_of_its_file_overlap(bohai_dir, tmp_path):
    copy = tmp_path / "copy.csv"
    copy.write_bytes((bohai_dir / "20220822_0_0.csv").read_bytes())
    refused(tmp_path, "--train", "bohai/20220822_0_0", "--test", str(copy), "--data-dir", str(bohai_dir), *KF,
            match=f"bohai/20220822_0_0 and {copy} are the same data (sha256 db16c328bc2ffbc8), both reading 0..349.592 s")
