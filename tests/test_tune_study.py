"""A damaged ``study.db`` and a busy tune directory (issue 33 item 7): one line naming the file and
how to recompute it from the units (which then gives the same leaderboard, nothing computed
again); ``replay tune --wait`` waits for the tune holding the lock."""
import shutil
import sqlite3
import threading

import pytest
from click.testing import CliRunner

from replay.cli import main

ARGS = ["sim/linear", "--filters", "kf", "--split", "seeds", "--dataset-param", "steps=60",
        "-p", "task.q=log[0.01,10]", "-p", "task.r=log[0.1,20]", "--runs", "2", "--trials", "4", "-q"]


def tune(out, *extra):
    return CliRunner().invoke(main, ["tune", *ARGS, "--out", str(out), *extra])


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    out = tmp_path_factory.mktemp("tune") / "t"
    res = tune(out)
    assert res.exit_code == 0, res.output
    return out


def units(d):
    """Every stored unit file with its inode and mtime: a recomputed unit is written anew."""
    return {str(p.relative_to(d)): (p.stat().st_ino, p.stat().st_mtime_ns) for p in (d / "units").rglob("*")
            if p.is_file()}


def _sql(*statements):
    def damage(path):
        con = sqlite3.connect(path)
        for s in statements:
            con.execute(s)
        con.commit()
        con.close()

    return damage


DAMAGE = {
    "garbage": (lambda p: p.write_bytes(b"\x13" * 4096), "file is not a database"),
    "truncated": (lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]), "malformed"),
    "empty": (lambda p: p.write_bytes(b""), "no Optuna table studies"),
    "no values table": (_sql("DROP TABLE trial_values"), "no Optuna table trial_values"),
    "a parameter row unreadable": (_sql("UPDATE trial_params SET distribution_json = 'nope'"), "JSONDecodeError"),
    "a value lost": (_sql("DELETE FROM trial_values WHERE trial_id = 2"), "trial 1 is complete without a value"),
    "a parameter lost": (_sql("DELETE FROM trial_params WHERE trial_id = 3 AND param_name = 'task.r'"),
                         "trial 2 lacks its parameters"),
}


# each case is two tunes and a report (2-7 s): the fast subset keeps a file that is not a database, an
# empty one and a row lost (SQLite's error, Optuna's schema, our own check); the other damages are slow
FAST_DAMAGE = ("garbage", "empty", "a value lost")


@pytest.mark.parametrize("kind", [k if k in FAST_DAMAGE else pytest.param(k, marks=pytest.mark.slow) for k in DAMAGE])
def test_a_damaged_study_is_refused_naming_the_file_then_recomputed_from_the_units(done, tmp_path, kind):
    d = tmp_path / "t"
    shutil.copytree(done, d)
    damage, why = DAMAGE[kind]
    damage(d / "study.db")
    before, damaged_bytes = units(d), (d / "study.db").read_bytes()
    res = tune(d)
    line = res.output.strip()
    assert res.exit_code == 2 and line.startswith("replay: error: ") and "\n" not in line, res.output
    assert f"{d / 'study.db'}: damaged" in line and why in line and "Traceback" not in res.output, line
    assert f"to recompute it from {d / 'units'}, move it aside (mv {d / 'study.db'} " in line
    assert (d / "study.db").read_bytes() == damaged_bytes  # not written to, not repaired in place
    report = CliRunner().invoke(main, ["report", str(d)])
    assert report.exit_code == 2 and f"{d / 'study.db'}: damaged" in report.output and "Traceback" not in report.output
    (d / "study.db").rename(d / "study.db.damaged")  # what the line says to do
    res = tune(d)
    assert res.exit_code == 0, res.output
    assert (d / "leaderboard.csv").read_bytes() == (done / "leaderboard.csv").read_bytes()
    assert units(d) == before  # every trial replayed from its stored units, none computed again


def test_tune_waits_for_the_tune_holding_the_lock_with_wait(done, tmp_path):
    from replay.campaign.lock import locked

    d = tmp_path / "t"
    shutil.copytree(done, d)
    release, taken = threading.Event(), threading.Event()

    def other_tune():
        with locked(d):
            taken.set()
            release.wait(60)

    holder = threading.Thread(target=other_tune)
    holder.start()
    taken.wait(10)
    try:
        res = tune(d)
        line = res.output.strip()
        assert res.exit_code == 2 and "\n" not in line, res.output
        assert f"{d / 'campaign.lock'}: another replay tune process (pid " in line and "pass --wait" in line
        inode = (d / "campaign.lock").stat().st_ino
        seen = []

        def release_when_waited_for():  # /proc/locks marks a blocked flock with "->"
            for _ in range(6000):
                blocked = [ln for ln in open("/proc/locks") if "->" in ln and f":{inode} " in ln]
                if blocked:
                    seen.append(blocked[0])
                    break
                release.wait(0.01)
            release.set()

        threading.Thread(target=release_when_waited_for).start()
        res = tune(d, "--wait")
        assert res.exit_code == 0, res.output
        assert seen and "FLOCK" in seen[0]  # it was blocked on the lock until the holder released it
        assert (d / "leaderboard.csv").read_bytes() == (done / "leaderboard.csv").read_bytes()
    finally:
        release.set()
        holder.join()


def test_a_new_tune_directory_holding_only_the_lock_is_waited_for(tmp_path):
    """A tune that has taken its lock has not made study.db yet: ``--wait`` waits instead of
    calling the directory foreign."""
    d = tmp_path / "t"
    d.mkdir()
    (d / "campaign.lock").write_text("")
    res = tune(d, "--trials", "1")
    assert res.exit_code == 0, res.output
    (d / "study.db").unlink()
    (d / "tune.json").unlink()
    res = tune(d, "--trials", "1")  # the units and leaderboard of someone else's run: not a tune directory
    assert res.exit_code == 2 and "not a replay tune output (no study.db, no tune.json)" in res.output


# slow: a tune of a generated recording
@pytest.mark.slow
def test_tune_takes_mapping_like_eval(shared_dir, tmp_path, monkeypatch):
    """``replay tune --mapping FILE`` is ``--dataset-param mapping=<FILE's absolute path>`` (issue 35
    item 3): the same study, resumed with nothing to compute, the same leaderboard."""
    from pathlib import Path

    bag = shared_dir / "datasets" / "bags" / "robot_localization" / "test1.bag"
    mapping = Path(__file__).resolve().parents[1] / "docs" / "mappings" / "rl_test1_fusion.toml"
    monkeypatch.chdir(mapping.parent)  # a relative --mapping: resolved as replay eval does
    args = ["tune", str(bag), "--task", "fusion", "--filters", "ekf", "--train-segment", "0.6", "--first", "2000",
            "--runs", "1", "--trials", "2", "-p", "ekf.q_scale=log[0.1,10]", "-q", "--out", str(tmp_path / "t")]
    res = CliRunner().invoke(main, [*args, "--mapping", mapping.name])
    assert res.exit_code == 0, res.output
    import json

    asked = json.loads((tmp_path / "t" / "tune.json").read_text())
    assert [p["mapping"] for _, p in asked["train"] + asked["test"]] == [str(mapping)] * 2
    board, before = (tmp_path / "t" / "leaderboard.csv").read_bytes(), units(tmp_path / "t")
    res = CliRunner().invoke(main, [*args, "--dataset-param", f"mapping={mapping}"])
    assert res.exit_code == 0, res.output  # another configuration would be refused (its fingerprint)
    assert (tmp_path / "t" / "leaderboard.csv").read_bytes() == board and units(tmp_path / "t") == before
    rows = board.decode().splitlines()
    assert rows[1].split(",")[2:4] == ["ekf", "ekf (default)"] and "measurements" in board.decode()


HOT = """
import os, sqlite3, sys
con = sqlite3.connect(sys.argv[1], isolation_level=None)
con.execute("PRAGMA cache_size = 1")  # spill to the file: the journal holds the pages it overwrote
con.execute("BEGIN")
con.execute("CREATE TABLE junk (x)")
con.executemany("INSERT INTO junk VALUES (?)", [("x" * 500,)] * 2000)
con.execute("UPDATE trial_values SET value = value + 1")
os.kill(os.getpid(), 9)
"""


def test_a_journal_left_hot_by_a_killed_writer_is_not_damage(done, tmp_path):
    """``kill -9`` inside a write leaves ``study.db-journal``: SQLite rolls it back on the next open,
    so the tune resumes with the study as it was committed (a read-only check would call it damaged)."""
    import subprocess
    import sys

    d = tmp_path / "t"
    shutil.copytree(done, d)
    killed = subprocess.run([sys.executable, "-c", HOT, str(d / "study.db")])
    assert killed.returncode == -9 and (d / "study.db-journal").stat().st_size > 0
    res = tune(d)
    assert res.exit_code == 0, res.output
    assert (d / "leaderboard.csv").read_bytes() == (done / "leaderboard.csv").read_bytes()
