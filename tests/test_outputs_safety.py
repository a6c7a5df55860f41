"""Fault tests of ``replay eval``'s output set (replay/outputs/files.py, replay/util/files.py).

A full disk (a small tmpfs, or ``RLIMIT_FSIZE`` with SIGXFSZ ignored), a read-only file
system, and a kill -9 at each step of writing (fault hooks ``REPLAY_FAULT=<point>``, and a
real kill of a running ``replay eval``) must each leave, under the output's name, either the
complete previous set or the complete new one — never a mix — and never touch an input.
The tmpfs tests mount file systems and are skipped where ``mount`` is not permitted.
"""
from __future__ import annotations

import gzip
import hashlib
import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from replay import evaluate  # the API: keywords in, one EvalOptions record built
from replay.outputs.files import write_all
from replay.util.errors import ReplayError
from replay.util.staging import MARKER, publish_dir, recover


@pytest.fixture(scope="module")
def small():
    return evaluate("sim/ungm", task="ungm", filters=["ekf", "ukf"], runs=2, seed=0)


@pytest.fixture(scope="module")
def big():
    """About 170 kB of estimates (two files of about 80 kB): larger than the room the tests leave."""
    return evaluate("sim/ungm", task="ungm", filters=["ekf", "ukf"], runs=40, seed=1)


def tree(d: Path) -> dict:
    """relative path -> sha256 of every file under ``d``."""
    return {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(d.rglob("*")) if p.is_file()}


def complete(d: Path, ev) -> bool:
    """``d`` holds exactly the full set of ``ev``: marker, leaderboard, manifest, every estimate row."""
    mark = json.loads((d / MARKER).read_text())
    assert sorted(mark["files"]) == sorted(k for k in tree(d) if k != MARKER)
    assert (d / "leaderboard.csv").read_text().count("\n") == 1 + len(ev.results)
    assert json.loads((d / "manifest.json").read_text())["config"]["runs"] == ev.config["runs"]
    for r in ev.results:
        with gzip.open(d / "estimates" / f"{r.name}.csv.gz", "rt") as fh:
            assert sum(1 for _ in fh) == 1 + ev.config["runs"] * len(ev.t)
    return True


def leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if ".staging-" in p.name or ".old-" in p.name)


def test_new_set_replaces_old_as_a_whole(tmp_path, small):
    out = tmp_path / "out"
    write_all(small, out)
    assert complete(out, small)
    one = evaluate("sim/ungm", task="ungm", filters=["ekf"], runs=2, seed=0)
    write_all(one, out)
    assert complete(out, one)
    assert sorted(p.name for p in (out / "estimates").iterdir()) == ["ekf.csv.gz", "ekf_rmse_over_time.csv"]
    assert leftovers(tmp_path) == []


def test_fallback_swap_without_exchange(tmp_path, small, monkeypatch):
    out = tmp_path / "out"
    write_all(small, out)
    monkeypatch.setenv("REPLAY_NO_EXCHANGE", "1")
    one = evaluate("sim/ungm", task="ungm", filters=["ekf"], runs=3, seed=0)
    write_all(one, out)
    assert complete(out, one) and leftovers(tmp_path) == []


def test_file_too_large_leaves_old_set(tmp_path, small, big):
    """ENOSPC's twin without a mount: RLIMIT_FSIZE with SIGXFSZ ignored makes writes fail (EFBIG)."""
    out = tmp_path / "out"
    write_all(small, out)
    before = tree(out)
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (40_000, hard))
    try:
        with pytest.raises(ReplayError) as err:
            write_all(big, out)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, old_handler)
    assert "\n" not in str(err.value)
    assert str(err.value) == (f"output {out}: cannot write (File too large); "
                              "the previous output, if any, is unchanged")
    assert tree(out) == before and leftovers(tmp_path) == []


@pytest.fixture
def tmpfs(tmp_path):
    """A 4 MiB tmpfs mounted on tmp_path/fs (skipped where mount is not permitted)."""
    mnt = tmp_path / "fs"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mnt)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.decode().strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=True)


def fill(mnt: Path, leave: int) -> None:
    """Write a ballast file so that ``leave`` bytes stay free on ``mnt``."""
    st = os.statvfs(mnt)
    (mnt / "ballast").write_bytes(b"\0" * (st.f_bfree * st.f_frsize - leave))


def test_enospc_midway_leaves_old_set(tmpfs, small, big, monkeypatch):
    out = tmpfs / "out"
    write_all(small, out)
    before = tree(out)
    monkeypatch.setattr("replay.util.staging.MIN_FREE", 16 * 1024)  # the check before writing lets it start
    fill(tmpfs, 96 * 1024)  # ... and the 170 kB set does not fit
    with pytest.raises(ReplayError, match=r"cannot write \(No space left on device\); the previous output"):
        write_all(big, out)
    assert tree(out) == before and leftovers(tmpfs) == []
    (tmpfs / "ballast").unlink()
    write_all(big, out)  # with room, the new set replaces the old one
    assert complete(out, big)


def test_full_and_read_only_refused_before_computing(tmpfs, small, monkeypatch):
    from hostile import assert_refused

    def boom(*a, **k):
        raise AssertionError("computed although the output location was refused")

    out = tmpfs / "out"
    write_all(small, out)
    before = tree(out)
    # replay eval's one call (eval_job) binds evaluate at its import: patched there first (imported with the
    # real one bound), then at its source
    monkeypatch.setattr("replay.outputs.eval_job.evaluate", boom)
    monkeypatch.setattr("replay.run.evaluation.evaluate", boom)
    args = ["eval", "sim/ungm", "--task", "ungm", "--filters", "ekf", "-o", out]
    fill(tmpfs, 64 * 1024)
    assert_refused(args, r"--out .*/fs/out: not enough space on the file system of .*/fs/out \(\d+ bytes free, "
                         r"at least 1048576 needed\)$")
    (tmpfs / "ballast").unlink()
    subprocess.run(["mount", "-o", "remount,ro", str(tmpfs)], check=True)
    assert_refused(args, r"--out .*/fs/out: .*/fs/out is on a read-only file system$")
    with pytest.raises(ReplayError, match="read-only file system"):
        write_all(small, out)
    assert tree(out) == before


def killed_write(ev, out: Path, point: str, no_exchange: bool = False) -> None:
    """Write ``ev`` to ``out`` in a forked child that SIGKILLs itself at fault point ``point``."""
    pid = os.fork()
    if pid == 0:  # child: never returns into pytest
        try:
            os.environ["REPLAY_FAULT"] = point
            if no_exchange:
                os.environ["REPLAY_NO_EXCHANGE"] = "1"
            write_all(ev, out)
        finally:
            os._exit(3)
    _, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, status


@pytest.mark.parametrize("point, no_exchange, survivor", [
    ("written", False, "old"),   # every file staged, nothing published
    ("swapped", False, "new"),   # exchanged, the old set not yet removed
    ("written", True, "old"),
    ("aside", True, "old"),      # fallback: old moved aside, new not yet in place
])
def test_kill_at_each_step(tmp_path, small, point, no_exchange, survivor):
    out = tmp_path / "out"
    write_all(small, out)
    before = tree(out)
    one = evaluate("sim/ungm", task="ungm", filters=["ekf"], runs=3, seed=2)
    killed_write(one, out, point, no_exchange)
    assert leftovers(tmp_path)  # the dead writer's staging or moved-aside directory
    recover(out)  # what the next write does first
    assert leftovers(tmp_path) == []
    if survivor == "old":
        assert tree(out) == before
    else:
        assert complete(out, one)
    write_all(small, out)
    assert tree(out) == before and leftovers(tmp_path) == []


def test_kill_before_fallback_swap_then_next_write_recovers(tmp_path, small):
    """Killed with the old set moved aside: the next write puts it back before checking ownership."""
    out = tmp_path / "out"
    write_all(small, out)
    one = evaluate("sim/ungm", task="ungm", filters=["ekf"], runs=3, seed=2)
    killed_write(one, out, "aside", no_exchange=True)
    assert not out.exists()
    write_all(one, out)
    assert complete(out, one) and leftovers(tmp_path) == []


def test_publish_into_absent_and_empty_target(tmp_path):
    for target in (tmp_path / "absent", tmp_path / "empty"):
        if target.name == "empty":
            target.mkdir()
        stage = tmp_path / f".{target.name}.staging-{os.getpid()}"
        stage.mkdir()
        (stage / "a").write_text("1")
        publish_dir(stage, target)
        assert (target / "a").read_text() == "1" and not stage.exists()


@pytest.mark.slow
def test_kill_9_while_replay_eval_writes(tmp_path):
    """A real ``replay eval`` killed while its staging directory exists: the old set survives,
    the dataset file is untouched, the next run cleans up and publishes."""
    log = tmp_path / "lake.csv"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cli = [sys.executable, "-m", "replay.cli"]
    subprocess.run([*cli, "datasets", "make", "sim/lake-depth", "--out", log, "--seed", "0"], check=True,
                   capture_output=True, env=env)
    data = hashlib.sha256(log.read_bytes()).hexdigest()
    out = tmp_path / "out"
    args = [*cli, "eval", log, "--filters", "ekf", "-o", out, "--force"]
    subprocess.run([*args, "--runs", "1"], check=True, capture_output=True, env=env)
    before = tree(out)
    proc = subprocess.Popen([*args, "--runs", "30"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    deadline = time.monotonic() + 240
    while not leftovers(tmp_path) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    proc.kill()
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read()
    assert leftovers(tmp_path) == [f".out.staging-{proc.pid}"]  # killed while writing
    assert tree(out) == before
    res = subprocess.run([*args, "--runs", "2"], capture_output=True, text=True, env=env)
    assert res.returncode == 0, res.stderr
    assert leftovers(tmp_path) == []
    assert json.loads((out / "manifest.json").read_text())["config"]["runs"] == 2
    assert hashlib.sha256(log.read_bytes()).hexdigest() == data
