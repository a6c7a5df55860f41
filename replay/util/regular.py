"""Inputs must be regular files: a FIFO, a device or a socket is refused before it is read.

``/dev/zero`` never ends, a FIFO blocks until some writer appears (even ``open`` does), and
``/dev/urandom`` is endless noise; none of them is a data file. :func:`check_regular` looks
with ``stat`` (which never blocks) and :func:`read_bytes` opens without blocking and checks the
opened file again, so a path swapped after the check is still refused.
"""

from __future__ import annotations

import os
import stat

from replay.util.errors import DataError

KINDS = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a directory"),
)


def kind(mode: int) -> str:
    """What a non-regular file is, in words."""
    return next((word for test, word in KINDS if test(mode)), "not a regular file")


def _refuse(path, mode: int, what: str):
    return DataError(path, f"{kind(mode)}, not a regular file: refusing to read it as {what}")


def check_regular(path, what: str = "a data file", *, dir_ok: bool = False) -> None:
    """Refuse ``path`` (one line naming it) unless it is a regular file (a directory too when
    ``dir_ok``), following symbolic links. A missing path is left to the caller."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return
    if stat.S_ISREG(mode) or (dir_ok and stat.S_ISDIR(mode)):
        return
    raise _refuse(path, mode, what)


def read_bytes(path, what: str = "a data file") -> bytes:
    """The bytes of the regular file ``path``; anything else is refused before reading
    (``FileNotFoundError`` and other ``OSError`` propagate for the caller to word)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise _refuse(path, mode, what)
        with os.fdopen(fd, "rb", closefd=False) as fh:
            return fh.read()
    finally:
        os.close(fd)
