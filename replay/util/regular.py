"""Inputs must be regular files: a FIFO, a device or a socket is refused before it is read.

``/dev/zero`` never ends, a FIFO blocks until some writer appears (even ``open`` does), and
``/dev/urandom`` is endless noise; none of them is a data file. :func:`check_regular` looks
with ``stat`` (which never blocks) and :func:`read_bytes` opens without blocking and checks the
opened file again, so a path swapped after the check is still refused. :func:`read_text` is the
one reader of the small text files a user names (mappings, campaign files, ``--space``,
``--tuned``, dataset manifests): a regular file of at most :data:`MAX_TEXT` bytes of UTF-8.
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


MAX_TEXT = 16 * 2**20  # bytes: a mapping, a campaign or a search space is a few kB


def read_bytes(path, what: str = "a data file", limit: int | None = None) -> bytes:
    """The bytes of the regular file ``path``; anything else (or, with ``limit``, a file larger
    than ``limit`` bytes) is refused before reading (``FileNotFoundError`` and other ``OSError``
    propagate for the caller to word)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise _refuse(path, info.st_mode, what)
        with os.fdopen(fd, "rb", closefd=False) as fh:
            data = fh.read() if limit is None else fh.read(limit + 1)
        if limit is not None and max(len(data), info.st_size) > limit:
            raise DataError(path, f"larger than {limit} bytes: refusing to read it as {what}")
        return data
    finally:
        os.close(fd)


def read_text(path, what: str, source=None, limit: int = MAX_TEXT) -> str:
    """The UTF-8 text of the small regular file ``path`` (at most ``limit`` bytes), or one
    line naming it (``source``: how the user named it, e.g. ``--space FILE``): missing, a
    directory, a FIFO or a device, too large, unreadable or not UTF-8 text."""
    source = path if source is None else source
    try:
        raw = read_bytes(path, what, limit)
    except DataError as e:
        raise DataError(source, str(e).removeprefix(f"{path}: ")) from None
    except FileNotFoundError:
        raise DataError(source, f"no such file (expected {what})") from None
    except OSError as e:
        raise DataError(source, f"cannot read {what}: {e.strerror}") from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise DataError(source, f"not {what} (not UTF-8 text: byte {e.start})") from None
