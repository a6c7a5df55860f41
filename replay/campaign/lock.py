"""One campaign process per result directory: an exclusive ``flock`` on ``OUT/campaign.lock``.

Two ``replay campaign run`` processes on one output would compute the same
units twice and interleave their leaderboards. The process that runs takes the
lock for its whole run and writes its pid into the lock file; a second one
refuses in one line naming the lock file and the holder's pid, or, with
``wait=True`` (``--wait``), blocks until the first has finished. The kernel
releases the lock when its holder exits, even on SIGKILL, so a crashed run
never leaves a stale lock; the file itself stays (removing it would race with a
process about to lock it). :func:`lock_file` is the same lock on any file (or
directory): ``replay eval`` holds it on its ``--out`` and its numbered run directories
(:mod:`replay.outputs.rundirs`).
"""

from __future__ import annotations

import errno
import os
from contextlib import contextmanager
from pathlib import Path

from replay.util.errors import ReplayError

LOCK_NAME = "campaign.lock"
KIND = "replay campaign"
OWN = {LOCK_NAME, "campaign.toml", "configs.json", "units", "leaderboard.csv", "paired.csv", "tune", "report"}
CORE = {LOCK_NAME, "configs.json", "units"}  # one of these is there from the first moment of a run


def campaign_dir(path: Path) -> bool:
    """Whether the directory ``path`` is a campaign's result directory (``replay campaign run --out``
    checks it with :func:`replay.util.staging.check_output_dir`, the rule of ``replay eval --out``):
    every entry one the campaign writes (:data:`OWN`, or a ``.NAME.PID.tmp`` of a write) and one of
    :data:`CORE` present. Anything else in it is someone else's, and the directory is refused."""
    try:
        names = os.listdir(path)
    except OSError:
        return False
    own = all(n in OWN or (n.startswith(".") and n.endswith(".tmp")) for n in names)
    return own and bool(CORE & set(names))


def holder(path: Path) -> str:
    """The pid recorded in a lock file, or ``unknown``."""
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return "unknown"
    return text if text.isdigit() else "unknown"


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


@contextmanager
def lock_file(path, wait: bool = False, *, busy: str, what: str = "the lock"):
    """Hold an exclusive ``flock`` on ``path`` for the block (created if absent; the holder's pid
    written into it). Held by another process: ``ReplayError(busy.format(pid=...))``, or with
    ``wait`` block until it is released. A directory ``path`` is locked itself (no pid recorded)."""
    import fcntl

    path = Path(path)
    is_dir = path.is_dir()
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY) if is_dir else os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as err:
        raise ReplayError(f"{path}: cannot open {what} ({err.strerror})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except OSError as err:
            if err.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise ReplayError(f"{path}: cannot lock ({err.strerror})") from None
            raise ReplayError(busy.format(pid=holder(path))) from None
        if not is_dir:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        try:
            yield path
        finally:
            if not is_dir:
                os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def held(path) -> bool:
    """Whether another process holds the lock of ``path`` (an existing lock file; False if absent)."""
    import fcntl

    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as err:
        return err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES)
    finally:
        os.close(fd)  # closing releases a lock this probe took
    return False
