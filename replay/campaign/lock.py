"""One campaign process per result directory: an exclusive ``flock`` on ``OUT/campaign.lock``.

Two ``replay campaign run`` processes on one output would compute the same
units twice and interleave their leaderboards. The process that runs takes the
lock for its whole run and writes its pid into the lock file; a second one
refuses in one line naming the lock file and the holder's pid, or, with
``wait=True`` (``--wait``), blocks until the first has finished. The kernel
releases the lock when its holder exits, even on SIGKILL, so a crashed run
never leaves a stale lock; the file itself stays (removing it would race with a
process about to lock it). It is :func:`replay.util.lock.lock_file`, the one lock of every
output (:class:`replay.util.output_set.OutputSet`).
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

from replay.util.lock import held, holder, lock_file  # noqa: F401 (held, holder: re-exported)
from replay.util.output_set import OutputSet

LOCK_NAME = "campaign.lock"
KIND = "replay campaign"
OWN = {LOCK_NAME, "campaign.toml", "configs.json", "units", "leaderboard.csv", "paired.csv", "tune", "report"}
CORE = {LOCK_NAME, "configs.json", "units"}  # one of these is there from the first moment of a run


def campaign_dir(path: Path) -> bool:
    """Whether the directory ``path`` is a campaign's result directory (``replay campaign run --out``
    checks it with :func:`output_set`, the rule of ``replay eval --out``):
    every entry one the campaign writes (:data:`OWN`, or a ``.NAME.PID.tmp`` of a write) and one of
    :data:`CORE` present. Anything else in it is someone else's, and the directory is refused."""
    try:
        names = os.listdir(path)
    except OSError:
        return False
    own = all(n in OWN or (n.startswith(".") and n.endswith(".tmp")) for n in names)
    return own and bool(CORE & set(names))


@contextmanager
def locked(out, wait: bool = False, who: str = "campaign"):
    """Hold the campaign lock of result directory ``out`` (which must exist) for the block
    (``who``: what the other process is, in the refusal)."""
    path = Path(out) / LOCK_NAME
    with lock_file(
        path,
        wait,
        busy=f"{path}: another {who} process (pid {{pid}}) is writing to {out}; wait for it to finish or pass --wait",
        what="the campaign lock",
    ) as p:
        yield p


def output_set(out, inputs=(), what: str = "--out") -> OutputSet:
    """The result directory ``out`` of a campaign as an :class:`OutputSet` (``check()`` it before
    any unit): never onto or inside the data; absent, empty, or a campaign's own directory."""
    return OutputSet(out, KIND, what=what, inputs=inputs, legacy=campaign_dir)
