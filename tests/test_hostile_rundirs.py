"""Concurrent and hostile ``replay eval`` output directories, and what the printed table must say
(corpus: tests/hostile.py; issue 23 items 1, 9, 10, 13).

Numbered run directories are claimed when a run starts and checked again at publication, ``--out``
is held by one writer at a time (a second refuses naming the holder's pid, or waits with
``--wait``), ``latest`` moves to the newest finished set; the table shows the share of the
reference scored (flagged under ``min_scored_share``) and says when identical runs are one run.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from hostile import assert_ok, assert_refused, register

from replay.util.errors import ReplayError

SIM = ["sim/ungm", "--task", "ungm", "--filters", "ekf"]
REPLAY = [sys.executable, "-m", "replay.cli"]
BASE = Path("runs") / "sim_ungm" / "ungm"

register("eval-8-concurrent-numbered", "eval-8-onto-one-out", "eval-8-onto-one-out-wait", "eval-live-claim",
         "eval-dead-claim-and-staging", "eval-out-locked", "eval-out-300-chars", "eval-out-component-too-long",
         "eval-out-path-too-long", "eval-leaderboard-csv-is-directory", "eval-data-dir-nowhere",
         "eval-data-dir-file", "eval-deterministic-runs", "eval-mostly-masked-reference",
         "eval-min-scored-share-invalid")


def _complete(d: Path) -> dict:
    """The manifest of a complete eval set in ``d`` (its marker lists exactly the files there)."""
    mark = json.loads((d / ".replay-output.json").read_text())
    files = sorted(str(p.relative_to(d).as_posix()) for p in d.rglob("*") if p.is_file())
    assert sorted(mark["files"] + [".replay-output.json"]) == files
    assert {"leaderboard.csv", "manifest.json"} <= set(files)
    return json.loads((d / "manifest.json").read_text())


def _spawn(args, cwd):
    return subprocess.Popen([*REPLAY, *map(str, args)], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


@pytest.mark.slow
def test_eight_concurrent_evals_leave_eight_complete_distinct_sets(tmp_path):
    procs = [_spawn(["eval", *SIM, "--runs", 2, "--seed", i, "-q"], tmp_path) for i in range(8)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0] * 8, outs
    base = tmp_path / BASE
    assert sorted(os.listdir(base)) == [f"{i:03d}" for i in range(1, 9)] + ["latest"]  # no claim or staging left
    seeds = sorted(_complete(base / f"{i:03d}")["config"]["seed"] for i in range(1, 9))
    assert seeds == list(range(8))  # 8 distinct sets: none overwrote another
    wrote = sorted(re.search(r"wrote (\S+)/leaderboard\.csv", o).group(1) for o, _ in outs)
    assert wrote == [str(BASE / f"{i:03d}") for i in range(1, 9)]  # each run printed its own directory
    assert os.readlink(base / "latest") == "008"


@pytest.mark.slow
def test_eight_onto_one_new_out_one_succeeds_others_refuse(tmp_path):
    procs = [_spawn(["eval", *SIM, "--runs", 2, "--seed", i, "-q", "-o", "res"], tmp_path) for i in range(8)]
    outs = [p.communicate(timeout=600) for p in procs]
    ok = [i for i, p in enumerate(procs) if p.returncode == 0]
    assert len(ok) == 1, outs
    for i, (p, (_, err)) in enumerate(zip(procs, outs)):
        if i in ok:
            continue
        lines = err.strip().splitlines()
        assert p.returncode == 2 and len(lines) == 1 and "Traceback" not in err, err
        assert re.fullmatch(r"replay: error: --out res: (another replay eval process \(pid \d+\) is writing to it; "
                            r"wait for it to finish or pass --wait|holds an earlier replay eval output; .*)", lines[0])
    assert _complete(tmp_path / "res")["config"]["seed"] == ok[0]


@pytest.mark.slow
def test_eight_onto_one_out_with_wait_all_succeed_in_turn(tmp_path):
    procs = [_spawn(["eval", *SIM, "--runs", 2, "--seed", i, "-q", "-o", "res", "--wait", "--force"], tmp_path)
             for i in range(8)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0] * 8, outs
    assert _complete(tmp_path / "res")["config"]["seed"] in range(8)
    assert sorted(os.listdir(tmp_path)) == [".res.lock", "res"]  # no staging left; the lock file stays


HOLD = """
import sys
from replay.outputs.rundirs import claimed_run_dir
with claimed_run_dir("sim/ungm", "ungm") as d:
    print(d, flush=True)
    sys.stdin.readline()
"""


def test_live_claim_is_not_taken_and_a_dead_one_is_cleaned(tmp_path, monkeypatch):
    """A directory claimed by a running process: the next run takes the next number, and writing
    onto it is refused naming the pid; once that process is killed, its claim is removed."""
    from replay.outputs.rundirs import claimed_run_dir

    holder = subprocess.Popen([sys.executable, "-c", HOLD], cwd=tmp_path, stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == str(BASE / "001")
        monkeypatch.chdir(tmp_path)
        with claimed_run_dir("sim/ungm", "ungm") as mine:
            assert mine == BASE / "002"
        assert not mine.exists()  # nothing published: the claim is removed with the block
        assert_refused(["eval", *SIM, "-o", BASE / "001", "--force"],
                       rf"^replay: error: --out {BASE}/001: another replay eval process \(pid {holder.pid}\) "
                       r"is computing into it; choose another --out$", cwd=tmp_path)
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert os.listdir(tmp_path / BASE / "001") == [".replay-claim"]  # left by the killed process
    assert_ok(["eval", *SIM, "--runs", 1], cwd=tmp_path)
    assert sorted(os.listdir(tmp_path / BASE)) == ["001", "latest"]  # the dead claim was replaced
    _complete(tmp_path / BASE / "001")


def test_crash_leftovers_do_not_break_later_runs(tmp_path):
    """A claim of a dead process, an empty numbered directory, a dead staging directory and a
    half-made ``latest`` link are removed by the next run, which publishes a complete set."""
    base = tmp_path / BASE
    (base / "001").mkdir(parents=True)
    (base / "001" / ".replay-claim").write_text("999999999\n")  # nobody holds its lock
    (base / "002").mkdir()
    (base / ".002.staging-999999999").mkdir()
    (base / ".002.staging-999999999" / "leaderboard.csv").write_text("half")
    os.symlink("002", base / ".latest.999999999.tmp")  # killed between making the link and renaming it
    assert_ok(["eval", *SIM, "--runs", 1], cwd=tmp_path)
    assert sorted(os.listdir(base)) == ["001", "latest"]
    _complete(base / "001")


def test_latest_points_to_the_newest_finished_set(tmp_path, monkeypatch):
    """A run that finishes after a newer one does not move ``latest`` back to itself."""
    import replay
    from replay.outputs.files import write_all
    from replay.outputs.rundirs import claimed_run_dir, mark_latest

    monkeypatch.chdir(tmp_path)
    ev = replay.evaluate("sim/ungm", filters=["ekf"], runs=1)
    with claimed_run_dir("sim/ungm", "ungm") as older, claimed_run_dir("sim/ungm", "ungm") as newer:
        write_all(ev, newer)
        mark_latest(newer)
        write_all(ev, older)
        mark_latest(older)
    assert (older.name, newer.name) == ("001", "002")
    assert os.readlink(tmp_path / BASE / "latest") == "002"
    assert sorted(os.listdir(tmp_path / BASE)) == ["001", "002", "latest"]


def test_out_held_by_another_writer_is_refused_with_its_pid(tmp_path, monkeypatch):
    from replay.outputs.rundirs import out_locked

    monkeypatch.chdir(tmp_path)
    with out_locked("res"):
        assert_refused(["eval", *SIM, "-o", "res"], rf"^replay: error: --out res: another replay eval process "
                       rf"\(pid {os.getpid()}\) is writing to it; wait for it to finish or pass --wait$")
    assert not (tmp_path / "res").exists()


def test_names_longer_than_the_file_system_allows_are_refused(tmp_path):
    assert_refused(["eval", *SIM, "-o", "a" * 300], r"^replay: error: --out a{40}\.\.\.a{12}: a name of 300 bytes "
                   r"\(a{20}\.\.\.\); at most 238 fit here$", cwd=tmp_path)
    assert_refused(["eval", *SIM, "-o", f"{'b' * 256}/run"], r"--out b{40}\.\.\..*: a name of 256 bytes .*at most 255",
                   cwd=tmp_path)
    assert_refused(["eval", *SIM, "-o", "/".join(["c" * 200] * 25)], r"--out c{40}.*: the path is \d+ bytes; at most",
                   cwd=tmp_path)
    assert os.listdir(tmp_path) == []


def test_leaderboard_csv_that_is_a_directory_is_refused(tmp_path):
    assert_ok(["eval", *SIM, "--runs", 1, "-o", "run"], cwd=tmp_path)
    (tmp_path / "run" / "leaderboard.csv").unlink()
    (tmp_path / "run" / "leaderboard.csv").mkdir()
    (tmp_path / "run" / "leaderboard.csv" / "x").write_text("user data")
    assert_refused(["eval", *SIM, "-o", "run", "--force"], r"--out run: holds 'leaderboard\.csv/x', which is not "
                   r"part of the replay eval output", cwd=tmp_path)
    assert_refused(["leaderboard", "run"], r"run: .*leaderboard\.csv", cwd=tmp_path)
    assert (tmp_path / "run" / "leaderboard.csv" / "x").read_text() == "user data"


def test_data_dir_that_is_not_a_directory_is_refused(tmp_path, monkeypatch):
    (tmp_path / "f.txt").write_text("x")
    assert_refused(["eval", *SIM, "--data-dir", "nowhere"], r"^replay: error: --data-dir nowhere: no such directory$",
                   cwd=tmp_path)
    assert_refused(["eval", *SIM, "--data-dir", "f.txt"], r"--data-dir f\.txt: is a file, not a directory$",
                   cwd=tmp_path)
    import replay

    monkeypatch.chdir(tmp_path)
    with pytest.raises(ReplayError, match=r"^data_dir nowhere: no such directory$"):
        replay.evaluate("sim/ungm", filters=["ekf"], data_dir="nowhere")
    assert sorted(os.listdir(tmp_path)) == ["f.txt"]


@pytest.fixture(scope="module")
def lake(tmp_path_factory):
    d = tmp_path_factory.mktemp("lake")
    assert_ok(["datasets", "make", "sim/lake-depth", "--out", d / "lake.csv", "--seed", 0])
    lines = (d / "lake.csv").read_text().splitlines()
    n = sum(ln.startswith("#") for ln in lines) + 1
    cols = lines[n - 1].split(",")
    refs = [i for i, c in enumerate(cols) if c.startswith("ref_")]
    masked = lines[:n]
    for k, ln in enumerate(lines[n:]):  # the reference only in the first 8 rows
        cells = ln.split(",")
        masked.append(",".join("" if k >= 8 and i in refs else c for i, c in enumerate(cells)))
    (d / "masked.csv").write_text("\n".join(masked) + "\n")
    return d


def test_identical_runs_say_deterministic_not_plus_minus_zero(lake, tmp_path):
    res = assert_ok(["eval", lake / "lake.csv", "--adapter", "lake", "--filters", "ekf", "--runs", 5, "-q", "-o",
                     tmp_path / "o"])
    assert "±" not in res.stdout.split("\nRMSE:")[0]
    assert "ekf: deterministic: 1 distinct run (the 5 runs are identical up to rounding; interval 0)" in res.stdout
    import csv

    row = next(csv.DictReader(open(tmp_path / "o" / "leaderboard.csv")))
    assert float(row["pos_rmse_ci95"]) == 0.0 and row["runs"] == "5"  # the CSV columns are unchanged


def _table(text: str) -> tuple[str, str]:
    """(the table's column header, its first row): the lines after the title's notes (reference, defaults)."""
    lines = text.splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith("filter "))
    return lines[i], lines[i + 1]


def test_mostly_masked_reference_is_flagged(lake, tmp_path):
    """7 of 1800 reference samples left (99.6 % masked): the row is flagged, not shown as a full result."""
    res = assert_ok(["eval", lake / "masked.csv", "--adapter", "lake", "--filters", "ekf", "-q", "-o", tmp_path / "o"])
    head, row = _table(res.stdout)
    assert head.split()[-1] == "scored" and row.split()[-1] == "0.4%!"
    assert ("ekf: scored on 7 of 1800 reference samples (0.4%; the rest masked), under min_scored_share=0.5: "
            "its numbers describe only the samples scored") in res.stdout
    assert json.loads((tmp_path / "o" / "manifest.json").read_text())["config"]["min_scored_share"] == 0.5
    full = assert_ok(["eval", lake / "lake.csv", "--adapter", "lake", "--filters", "ekf", "-q", "-o", tmp_path / "p"])
    assert _table(full.stdout)[1].split()[-1] == "97.7%" and "scored on" not in full.stdout
    low = assert_ok(["eval", lake / "masked.csv", "--adapter", "lake", "--filters", "ekf", "-q", "-o", tmp_path / "q",
                     "--min-scored-share", "0.001"])
    assert _table(low.stdout)[1].split()[-1] == "0.4%"


def test_bohai_cut_case_is_flagged(tmp_path):
    """11 of 3000 samples scored (the Bohai cut of the issue): ``0.4%!`` and the warning line."""
    import replay
    from replay.outputs.files import format_table

    ev = replay.evaluate("sim/ungm", filters=["ekf"], runs=1)
    ev.rows[0].update(scored=11, masked=2989)
    text = format_table(ev)
    assert _table(text)[1].split()[-1] == "0.4%!"
    assert "ekf: scored on 11 of 3000 reference samples (0.4%; the rest masked)" in text


@pytest.mark.parametrize("value", ["1.5", "-0.1", "nan", "inf"])
def test_min_scored_share_out_of_range_is_refused(value, tmp_path):
    assert_refused(["eval", *SIM, "--min-scored-share", value],
                   r"^replay: error: --min-scored-share: min_scored_share must be a finite number in \[0, 1\]",
                   cwd=tmp_path)
    import replay

    with pytest.raises(ReplayError, match=r"min_scored_share must be a finite number in \[0, 1\]"):
        replay.evaluate("sim/ungm", filters=["ekf"], min_scored_share=float(value))
