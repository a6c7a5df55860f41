"""Issue 33, items 2, 3, 6 and 10 (parts): every archive a command reads is verified (results.json
included), outputs never overwrite what they did not create, stamps survive conversion exactly,
short downloads are never stored, campaign_results and campaign --out refuse foreign paths."""
from __future__ import annotations

import json

import numpy as np
import pytest

from replay.trajectory.base import make
from replay.trajectory.files import write_tum
from replay.util import sealed

from cli_helpers import ok, refused




@pytest.fixture
def files(tmp_path):
    n = 60
    t = 10.0 + np.arange(n) * 0.1
    s = np.arange(n, dtype=float)
    p = np.column_stack([s, np.sin(s / 5), np.zeros(n)])
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    write_tum(tmp_path / "gt.tum", make(t, p, q, source="gt"))
    write_tum(tmp_path / "est.tum", make(t, p * 1.01, q, source="est"))
    return tmp_path


@pytest.fixture
def saved(files):
    out = files / "res"
    ok(["score", files / "gt.tum", files / "est.tum", "--save-results", out])
    return out, json.loads((out / "results.json").read_text())


def _write(out, meta, reseal=False):
    if reseal:
        meta = dict(meta, results_sha256=sealed.digest(meta, "results_sha256"))
    (out / "results.json").write_text(json.dumps(meta, indent=1))


def test_an_edited_statistic_is_refused(saved):
    out, meta = saved
    rmse = meta["estimates"][0]["stats"]["ape"]["trans"]["rmse"]
    assert rmse > 0.1
    table = ok(["res", out, "--format", "csv"])
    assert repr(rmse) in table or f"{rmse}" in table
    edited = json.loads(json.dumps(meta))
    edited["estimates"][0]["stats"]["ape"]["trans"]["rmse"] = 0.001
    _write(out, edited)
    refused(["res", out], "results.json: content differs from its SHA-256 (results_sha256): edited or damaged")
    _write(out, meta)  # re-indented, same values: still verified
    assert ok(["res", out, "--format", "csv"]) == table


def test_a_resealed_edit_disagrees_with_the_errors_kept(files):
    """An edit whose seal was recomputed (the checksum is not a signature): the statistics are recomputed
    from ape.parquet / rpe.parquet and must agree."""
    out = files / "rpe"
    ok(["score", files / "gt.tum", files / "est.tum", "--rpe", "--save-results", out])
    meta = json.loads((out / "results.json").read_text())
    assert set(meta["estimates"][0]["stats"]) == {"ape", "rpe"}
    table = ok(["res", out, "--format", "csv"])
    for kind, key in (("ape", "rmse"), ("rpe", "mean"), ("ape", "n")):
        edited = json.loads(json.dumps(meta))
        st = edited["estimates"][0]["stats"][kind]["trans"]
        st[key] = 0.001 if key != "n" else st[key] - 1
        _write(out, edited, reseal=True)
        refused(["res", out], f"results.json: est {kind} trans {key} ")
    _write(out, meta)
    assert ok(["res", out, "--format", "csv"]) == table


def test_an_emptied_file_list_is_refused(saved):
    out, meta = saved
    _write(out, dict(meta, files={}))
    refused(["res", out], "content differs from its SHA-256")
    _write(out, dict(meta, files={}), reseal=True)
    refused(["res", out], "results.json: lists no files (every archive holds ape.parquet, leaderboard.csv)")
    files = {k: v for k, v in meta["files"].items() if k != "ape.parquet"}
    _write(out, dict(meta, files=files), reseal=True)
    refused(["res", out], "does not list ape.parquet")
    _write(out, dict(meta, files=dict(meta["files"], **{"results.json": "0" * 64})), reseal=True)
    refused(["res", out], "results.json is missing (listed in results.json)")


def test_a_version_1_archive_is_refused_saying_how_to_recreate_it(saved):
    out, meta = saved
    old = {k: v for k, v in meta.items() if k != "results_sha256"}
    _write(out, dict(old, version=1))
    line = refused(["res", out], "archive version 1")
    assert "recreate it with replay score REF EST... --save-results" in line


STAMPS_NS = [1403636579758555392, 1403636579763555584, 1403636579768555520, 1403636579773555712,
             1403636579778555392]


def _euroc(path, stamps_ns):
    rows = [f"{k},{0.1 * i},{-0.2 * i},{0.3},1.0,0.0,0.0,0.0" for i, k in enumerate(stamps_ns)]
    path.write_text("#timestamp [ns],p_x,p_y,p_z,q_w,q_x,q_y,q_z\n" + "\n".join(rows) + "\n")
    return path


def _exact_ns(spec, **kw):
    from replay.trajectory import io

    return io.load(str(spec), exact=True, **kw).ns.tolist()


@pytest.mark.parametrize("name, fmt", [("o.tum", None), ("k/o.kitti", None), ("o.csv", None),
                                       ("o_euroc.csv", "euroc"), ("o.mcap", None)])
def test_integer_nanoseconds_survive_every_format(tmp_path, name, fmt):
    src = _euroc(tmp_path / "data.csv", STAMPS_NS)
    out = tmp_path / name
    ok(["convert", src, out, *(["--format", fmt] if fmt else []), "--in-format", "euroc"])
    back = f"{out}:/pose" if name.endswith(".mcap") else out
    assert _exact_ns(back, **({"fmt": fmt} if fmt else {})) == STAMPS_NS
    if name.endswith(".tum"):  # written as decimal seconds, not the float's 17 digits
        assert out.read_text().splitlines()[1].split()[0] == "1403636579.758555392"
    # and back to EuRoC: the very integers
    again = tmp_path / "again.csv"
    ok(["convert", back, again, "--format", "euroc"])
    assert [int(line.split(",")[0]) for line in again.read_text().splitlines()[1:]] == STAMPS_NS


def test_odd_fractional_seconds_survive(tmp_path):
    stamps = ["0.1", "0.30000000000000004", "1.0000000005", "1.0000000015", "12.3456789012345", "1403636579.758555392"]
    src = tmp_path / "a.tum"
    src.write_text("".join(f"{s} {k} 0 0 0 0 0 1\n" for k, s in enumerate(stamps)))
    ok(["convert", src, tmp_path / "e.csv", "--format", "euroc"])
    got = [int(line.split(",")[0]) for line in (tmp_path / "e.csv").read_text().splitlines()[1:]]
    # to the nearest ns, ties to even: 1.0000000005 -> ...000, 1.0000000015 -> ...002
    assert got == [100000000, 300000000, 1000000000, 1000000002, 12345678901, 1403636579758555392]
    ok(["convert", src, tmp_path / "b.tum"])
    from replay.trajectory import io

    a, b = io.load(str(src)), io.load(str(tmp_path / "b.tum"))
    assert np.array_equal(a.t, b.t)  # the floats too: the shortest text where it is the same ns
    assert _exact_ns(tmp_path / "b.tum") == got


def test_kitti_times_of_other_poses_are_never_overwritten(files):
    gt = files / "gt.tum"
    other = files / "other.tum"
    write_tum(other, make(20.0 + np.arange(60) * 0.1, np.eye(60, 3), np.tile([0.0, 0, 0, 1], (60, 1)), source="o"))
    ok(["convert", gt, files / "k" / "a.kitti"])
    times = (files / "k" / "times.txt").read_text()
    line = refused(["convert", other, files / "k" / "b.kitti"], "times.txt: exists and holds other stamps")
    assert "--force" in line and not (files / "k" / "b.kitti").exists()
    assert (files / "k" / "times.txt").read_text() == times
    ok(["convert", gt, files / "k" / "a2.kitti"])  # the same stamps: nothing re-timed
    ok(["convert", other, files / "k" / "b.kitti", "--force"])
    from replay.trajectory import io

    assert io.load(str(files / "k" / "b.kitti")).t[0] == 20.0


def test_campaign_results_refuses_what_is_not_a_result(files):
    """A trajectory, a foreign CSV, a binary file, an empty leaderboard: one line naming the file (was a
    table of NaN); runs=True on a file or a missing path: one line (was a traceback / an empty table)."""
    import replay
    from replay.util.errors import ReplayError

    (files / "other.csv").write_text("a,b\n1,2\n")
    (files / "bin.dat").write_bytes(b"\x00\xff\x01binary")
    (files / "head.csv").write_text("dataset,task,filter,runs,pos_rmse\n")
    ok(["score", files / "gt.tum", files / "est.tum", "-o", files / "lb.csv"])
    for name, message in (("gt.tum", "its header lacks dataset, task, filter, runs"),
                          ("other.csv", "its header lacks dataset, task, filter, runs"),
                          ("bin.dat", "not UTF-8 text"), ("head.csv", "an empty leaderboard")):
        with pytest.raises(ReplayError, match=message) as e:
            replay.campaign_results(files / name)
        assert str(files / name) in str(e.value) and "\n" not in str(e.value)
    df = replay.campaign_results(files / "lb.csv")
    assert len(df) == 1 and df["filter"].iloc[0] == "recorded:est" and df["pos_rmse"].iloc[0] > 0.1
    with pytest.raises(ReplayError, match="lb.csv: not a directory: runs=True reads the directory"):
        replay.campaign_results(files / "lb.csv", runs=True)
    with pytest.raises(ReplayError, match="absent: no such directory"):
        replay.campaign_results(files / "absent", runs=True)
    (files / "ev").mkdir()
    (files / "ev" / "runs.csv").write_text("x,y\n1,2\n")
    with pytest.raises(ReplayError, match=r"runs.csv: not the runs of a replay eval output \(its header lacks"):
        replay.campaign_results(files / "ev", runs=True)


CAMPAIGN = """\
[campaign]
name = "outs"
runs = 1
seed = 1

[[dataset]]
id = "sim/auv-sonar"
params = { steps = 20 }

[[filter]]
name = "ukf"
"""


def test_campaign_out_refuses_a_foreign_directory_as_eval_does(tmp_path):
    (tmp_path / "c.toml").write_text(CAMPAIGN)
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    camp = refused(["campaign", "run", tmp_path / "c.toml", "--out", foreign, "-w", "1", "-q"], "notes.txt")
    ev = refused(["eval", "sim/auv-sonar", "--filters", "ukf", "--runs", "1", "--out", foreign], "notes.txt")
    assert camp == ev.replace("replay eval output", "replay campaign output")  # one rule, one wording
    assert sorted(p.name for p in foreign.iterdir()) == ["notes.txt"] and (foreign / "notes.txt").read_text() == "keep me"
    # a campaign's own directory is run again; another kind of output is refused
    (foreign / "notes.txt").unlink()
    ok(["campaign", "run", tmp_path / "c.toml", "--out", foreign, "-w", "1", "-q"])
    assert "nothing to do" in ok(["campaign", "run", tmp_path / "c.toml", "--out", foreign, "-w", "1", "-q"])
    refused(["eval", "sim/auv-sonar", "--filters", "ukf", "--runs", "1", "--out", foreign],
            "not a replay eval output (it holds 'campaign.lock')")


def test_stamps_beyond_integer_nanoseconds(tmp_path):
    """3e12 s does not fit int64 ns: written in seconds as it is, refused for EuRoC and MCAP (was a wrapped
    integer, then a traceback) before anything is written."""
    src = tmp_path / "big.tum"
    src.write_text("".join(f"{k}e12 {k} 0 0 0 0 0 1\n" for k in (1, 2, 3)))
    ok(["convert", src, tmp_path / "o.tum"])
    assert [line.split()[0] for line in (tmp_path / "o.tum").read_text().splitlines()[1:]] == [
        "1000000000000.0", "2000000000000.0", "3000000000000.0"]
    for args in ([tmp_path / "o.mcap"], [tmp_path / "e.csv", "--format", "euroc"]):
        refused(["convert", src, *args], "big.tum: a stamp of 3e+12 s is beyond integer nanoseconds")
        assert not args[0].exists()
