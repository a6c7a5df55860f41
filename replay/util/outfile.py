"""One output file (``replay score -o``, ``--plot``): checked before the computation, written atomically.

:func:`check` refuses, in one line naming the option and the path, before anything is computed:
an extension the writer does not support, a path that is a directory or another non-regular file
(``/dev/stdout``, a FIFO: renaming a file onto it would replace it), a parent that is a file,
and a location where a file cannot actually be created (probed by creating and removing a
temporary file or directory there: permission bits alone do not tell, e.g. for root or a
read-only mount). Missing parent directories are fine: :func:`write` creates them, as ``mkdir -p``
would, then writes a temporary file beside the target, fsyncs it and renames it into place
(:class:`replay.util.output_set.OutputSet`), so a crash leaves the old file or the new one,
never a part. A symbolic link keeps pointing where it
did: the file it points to is replaced. Nothing is written under /dev, /proc or /sys (``-o
/dev/stdout`` would otherwise rename a file over the link itself), except in /dev/shm: a RAM file
system of regular files (the test suite's scratch space, tests/conftest.py).
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

from replay.util.errors import ReplayError
from replay.util.output_set import OutputSet
from replay.util.regular import kind

NAME_MAX = 230  # bytes of a file name: 255 on common file systems, less the temporary file's suffix


def _reason(e: OSError) -> str:
    return e.strerror or type(e).__name__


def check(path, what: str, suffixes=None) -> Path:
    """Refuse an output file that cannot be written (module docstring); returns it as a Path."""
    p = Path(path)
    if suffixes is not None and p.suffix.lower().lstrip(".") not in suffixes:
        shown = repr(p.suffix) if p.suffix else "none"
        raise ReplayError(
            f"{what} {path}: unsupported extension {shown} (supported: {', '.join('.' + s for s in suffixes)})"
        )
    sizes = [len(os.fsencode(part)) for part in p.parts]
    if sizes and (sizes[-1] > NAME_MAX or max(sizes) > 255):
        raise ReplayError(
            f"{what} {str(path)[:60]}...: a name of {max(sizes)} bytes in this path is too long "
            f"(at most {NAME_MAX} for the file, 255 for a directory)"
        )
    for q in (Path(os.path.abspath(p)), Path(os.path.realpath(p))):
        if q.parts[1:2] in (("dev",), ("proc",), ("sys",)) and q.parts[1:3] != ("dev", "shm"):  # /dev/stdout, devices
            raise ReplayError(
                f"{what} {path}: lies in /{q.parts[1]} (devices and kernel files), not a place for an output file"
            )
    if p.is_dir():
        raise ReplayError(f"{what} {path}: is a directory; give a file name")
    try:
        mode = os.stat(p).st_mode
    except OSError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode):  # /dev/stdout, a FIFO: never replaced by a file
        raise ReplayError(f"{what} {path}: {kind(mode)}, not a regular file: refusing to replace it")
    ancestor = next((q for q in p.parents if q.exists() or q.is_symlink()), Path("."))
    if not ancestor.is_dir():
        raise ReplayError(f"{what} {path}: {ancestor} is not a directory")
    try:
        if ancestor == p.parent:
            fd, probe = tempfile.mkstemp(prefix=f".{p.name[:40]}.", suffix=".probe", dir=ancestor)
            os.close(fd)
            os.unlink(probe)
        else:
            os.rmdir(tempfile.mkdtemp(prefix=".replay-probe.", dir=ancestor))
    except OSError as e:
        raise ReplayError(f"{what} {path}: cannot create a file in {ancestor} ({_reason(e)})") from None
    return p


def write(path, what: str, writer) -> Path:
    """``writer(tmp)`` writes the content to the temporary path ``tmp``; it is fsynced and renamed onto
    ``path`` (parents created) by :meth:`OutputSet.staged`. Any ``OSError`` is one line naming
    ``what`` and ``path``."""
    p = Path(os.path.realpath(path)) if os.path.islink(path) else Path(path)  # a link: its target replaced
    with OutputSet(p, what=what, rule=_checked, file=True, failed="cannot write ({why})").staged() as tmp:
        writer(tmp)
    return p


def _checked(path, shown) -> None:
    """The ownership rule of an output file: none beyond :func:`check` (any regular file is replaced)."""
