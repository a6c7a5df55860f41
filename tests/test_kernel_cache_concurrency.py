"""Many processes starting at once on a cold cache (issue 33, item 1): four or eight ``replay tune``,
``replay eval`` or campaign pools compiling the same kernels into empty caches, then a normal run.

Before, numba's cache of the model kernels could be left naming one signature beside another's code:
every later run segfaulted (exit 139) until ``replay/models/__pycache__`` was deleted by hand. Now
(replay.util.kernel_cache) every process must exit 0 with the numbers of a run that had a cache to
itself, the normal run after them too, and every numba file written must carry this user's seal.
Cold means a fresh ``REPLAY_CACHE_DIR`` (the bound copies) and a fresh ``NUMBA_CACHE_DIR`` (the
library's own kernels). Tiny workloads (60 steps, 2 runs): the cost is the compilation, so each
command runs two filters that between them compile both kinds of shared kernel: the EKF the
model's kernels (two signatures of ``f`` and of ``H`` in one index, as in the issue's crash) and the
STCPF those too and its bound copy of the paper-002 kernels (the issue's repro also ran pf, and the
eval ukf: more of the same kinds, a third more compilation per process; CPU seconds of one cold
eval process: 36.7 with ekf,ukf,pf,stcpf, 27.3 with ekf,stcpf).
"""
from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest

from replay.util.kernel_cache import unseal

pytestmark = pytest.mark.slow

REPLAY = [sys.executable, "-m", "replay.cli"]
TUNE = ["tune", "sim/auv-sonar", "--filters", "ekf,stcpf", "--split", "seeds", "--runs", "2",
        "--dataset-param", "steps=60", "--trials", "3", "-p", "ekf.q_scale=log[0.1,10]",
        "-p", "stcpf.q_scale=log[0.1,10]"]
EVAL = ["eval", "sim/auv-sonar", "--runs", "2", "--dataset-param", "steps=60", "--filters", "ekf,stcpf"]
CAMPAIGN = """[campaign]
runs = 2
[[dataset]]
id = "sim/auv-sonar"
params = { steps = 60 }
[[filter]]
name = "ekf"
[[filter]]
name = "stcpf"
"""
NUMBERS = ("filter", "params", "pos_rmse", "train", "test", "ate", "lost")  # the leaderboards' numbers


def _cmd(kind: str, out: Path, campaign: Path) -> list[str]:
    if kind == "tune":
        return [*REPLAY, *TUNE, "--out", str(out)]
    if kind == "eval":
        return [*REPLAY, *EVAL, "--out", str(out)]
    return [*REPLAY, "campaign", "run", str(campaign), "--workers", "2", "--out", str(out), "--quiet"]


def _board(out: Path) -> list[dict]:
    with open(out / "leaderboard.csv", newline="") as f:
        return [{k: v for k, v in row.items() if k in NUMBERS} for row in csv.DictReader(f)]


def _start(kind, out, campaign, caches: Path | None):
    """The command on the caches under ``caches`` (None: the test session's, which tests share)."""
    env = dict(os.environ)
    if caches is not None:
        env.update(REPLAY_CACHE_DIR=str(caches / "replay"), NUMBA_CACHE_DIR=str(caches / "numba"))
    return subprocess.Popen(_cmd(kind, out, campaign), env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def _finish(proc) -> None:
    text, _ = proc.communicate(timeout=1800)
    assert proc.returncode == 0, f"exit {proc.returncode}: {text[-2000:]}"


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Each command's leaderboard from a run on the test session's caches: one after the other,
    nothing concurrent, nothing shared with the cold caches of the tests below (a run's numbers
    do not depend on whether its kernels were compiled or loaded; the reference used a cold cache of
    its own before: three more cold compilations, ~70 CPU s, for the same numbers)."""
    base = tmp_path_factory.mktemp("reference")
    campaign = base / "c.toml"
    campaign.write_text(CAMPAIGN)
    boards = {}
    for kind in ("tune", "eval", "campaign"):
        proc = _start(kind, base / kind, campaign, None)
        _finish(proc)
        boards[kind] = _board(base / kind)
    return boards


# 4 and 8 concurrent cold starts of each command (issue 33's acceptance: every count with every command;
# the slowest test of the suite, each process compiling every kernel it needs).
@pytest.mark.parametrize("n", [4, 8])
@pytest.mark.parametrize("kind", ["tune", "eval", "campaign"])
def test_concurrent_cold_starts_leave_a_cache_every_later_run_uses(tmp_path, reference, kind, n):
    campaign = tmp_path / "c.toml"
    campaign.write_text(CAMPAIGN)
    caches = tmp_path / "caches"
    procs = [_start(kind, tmp_path / f"out{i}", campaign, caches) for i in range(n)]
    for proc in procs:
        _finish(proc)
    for i in range(n):
        assert _board(tmp_path / f"out{i}") == reference[kind]
    _finish(_start(kind, tmp_path / "after", campaign, caches))  # the normal run, on the cache they left
    assert _board(tmp_path / "after") == reference[kind]
    written = list(caches.rglob("*.nb[ic]"))
    names = [p.name for p in written]  # (with NUMBA_CACHE_DIR set numba keeps the copies' files there too)
    assert any(n.startswith("auv_sonar_kernels.") for n in names) and any(n.startswith("replay_") for n in names)
    assert all(unseal(p.read_bytes()) is not None for p in written)  # every file sealed with this user's key
