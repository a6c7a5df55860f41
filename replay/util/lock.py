"""An exclusive ``flock`` on a file or directory, held for a block; the one lock of every output.

The holder writes its pid into the lock file; a second process refuses in one line naming that
pid, or waits. The kernel releases the lock when its holder exits, even on SIGKILL, so a crashed
writer never leaves a stale lock; the file itself stays (removing it would race with a process
about to lock it). Used by :class:`replay.util.output_set.OutputSet` (``.NAME.lock`` beside an
output), the numbered run directories of ``replay eval`` and the campaign lock.
"""

from __future__ import annotations

import errno
import fcntl
import os
from contextlib import contextmanager
from pathlib import Path

from replay.util.errors import ReplayError


def holder(path: Path) -> str:
    """The pid recorded in a lock file, or ``unknown``."""
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return "unknown"
    return text if text.isdigit() else "unknown"


@contextmanager
def lock_file(path, wait: bool = False, *, busy: str, what: str = "the lock"):
    """Hold an exclusive ``flock`` on ``path`` for the block (created if absent; the holder's pid
    written into it). Held by another process: ``ReplayError(busy.format(pid=...))``, or with
    ``wait`` block until it is released. A directory ``path`` is locked itself (no pid recorded)."""
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
