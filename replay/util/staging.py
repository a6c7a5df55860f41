"""The steps under :class:`replay.util.output_set.OutputSet`: ownership, space, publish, recover.

A command that writes a set of files (``replay eval``: leaderboard, estimates, manifest) writes
them into a staging directory beside the target, ``<parent>/.<name>.staging-<pid>``, fsyncs them,
records what it wrote in an ownership marker (:data:`MARKER`) and moves the whole directory into
place in one step (:func:`publish_dir`). A crash, a kill or a full disk at any point leaves the
previous set or the new one under the target's name, never a mix; leftovers of dead processes are removed
(or, for an old set moved aside by the fallback swap, put back) by the next write.

Test hooks (fault injection, used by tests/test_outputs_safety.py): ``REPLAY_FAULT=<point>``
kills the process with SIGKILL at that point (``written``, ``aside``, ``swapped``);
``REPLAY_NO_EXCHANGE=1`` uses the fallback swap instead of renameat2(RENAME_EXCHANGE).
"""

from __future__ import annotations

import ctypes
import errno
import json
import os
import re
import shutil
import signal
import sys
from pathlib import Path

from replay.util.errors import ReplayError
from replay.util.files import shown


MARKER = ".replay-output.json"
MIN_FREE = 1 << 20  # bytes: a location with less free space than this is refused as full


def fault_point(point: str) -> None:
    if os.environ.get("REPLAY_FAULT") == point:
        os.kill(os.getpid(), signal.SIGKILL)


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (this process: yes; one of another user: yes, it cannot be signalled)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def fsync_path(path, directory: bool = False) -> None:
    fd = os.open(path, os.O_RDONLY | (os.O_DIRECTORY if directory else 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_tree(root) -> None:
    """fsync every file and directory under ``root`` (so that a rename publishes complete data)."""
    for dirpath, _dirs, files in os.walk(root):
        for f in files:
            fsync_path(os.path.join(dirpath, f))
        fsync_path(dirpath, directory=True)


def tree_files(root: Path) -> list[str]:
    return sorted(str(Path(d, f).relative_to(root).as_posix()) for d, _dirs, files in os.walk(root) for f in files)


def read_marker(path) -> dict | None:
    """The ownership marker of an output directory (``None`` without a readable one)."""
    try:
        mark = json.loads((Path(path) / MARKER).read_text())
    except (OSError, ValueError):
        return None
    return mark if isinstance(mark, dict) and mark.get("tool") == "replay" else None


def is_report_dir(entry: Path) -> bool:
    """``report/`` written into an output directory by ``replay report``: goes with its set."""
    return (
        entry.name == "report"
        and entry.is_dir()
        and not entry.is_symlink()
        and all(p.is_file() and (p.name == "report.html" or p.suffix == ".png") for p in entry.iterdir())
    )


def check_replaceable(target, kind: str, what: str = "output", legacy=None, shown=None) -> None:
    """Refuse ``target`` unless it is absent, an empty directory, or a whole ``kind`` output of ours.

    Ours: a directory whose marker (written by :meth:`replay.util.output_set.OutputSet.staged`)
    names ``kind`` and lists every file in it, or, for sets written before markers existed, one
    that ``legacy(path)`` accepts.
    A ``report/`` directory of ``replay report`` inside it is part of the set. Anything else —
    a file, a directory another program wrote, a set to which a file was added — is refused
    with one line (naming ``shown``, default ``target``), so that replacing the set never
    removes what the user put there.
    """
    p = Path(target)
    target = target if shown is None else shown
    if not os.path.lexists(p):
        return
    if not p.is_dir():
        raise ReplayError(f"{what} {target}: is a file, not a directory")
    try:
        cwd = Path.cwd().resolve()
    except OSError:
        cwd = None
    if cwd is not None and cwd.is_relative_to(p.resolve()):
        raise ReplayError(
            f"{what} {target}: holds the current directory, which replacing it as a whole "
            f"would remove; run from elsewhere or choose another {what}"
        )
    entries = sorted(p.iterdir())
    if not entries:
        return
    mark = read_marker(p)
    if mark is None:
        if legacy is not None and legacy(p):
            return
        raise ReplayError(
            f"{what} {target}: is a non-empty directory that is not a {kind} output "
            f"(it holds {entries[0].name!r}); refusing to replace it: choose another {what}"
        )
    if mark.get("kind") != kind:
        raise ReplayError(
            f"{what} {target}: holds a {mark.get('kind')!r} output, not a {kind} output; "
            f"refusing to replace it: choose another {what}"
        )
    listed = set(mark.get("files") or ()) | {MARKER}
    for e in entries:
        if is_report_dir(e):
            continue
        extra = [
            f
            for f in (
                [e.name]
                if not e.is_dir() or e.is_symlink()
                else [str(Path(e.name, f).as_posix()) for f in tree_files(e)]
            )
            if f not in listed
        ]
        if extra:
            raise ReplayError(
                f"{what} {target}: holds {extra[0]!r}, which is not part of the {kind} output; "
                f"refusing to replace the directory: move it away or choose another {what}"
            )


def check_space(out, what: str = "output", need: int | None = None) -> None:
    """Refuse an output location whose file system is read-only or has less than ``need`` bytes
    (default :data:`MIN_FREE`) free."""
    need = MIN_FREE if need is None else need
    p = Path(out).resolve()
    probe = next((q for q in (p, *p.parents) if q.is_dir()), None)
    if probe is None:
        return
    st = os.statvfs(probe)
    if st.f_flag & os.ST_RDONLY:
        raise ReplayError(f"{what} {out}: {shown(out, probe)} is on a read-only file system")
    free = (st.f_bfree if os.geteuid() == 0 else st.f_bavail) * st.f_frsize
    if free < need:
        raise ReplayError(
            f"{what} {out}: not enough space on the file system of {shown(out, probe)} "
            f"({free} bytes free, at least {need} needed)"
        )


def _leftovers(target: Path):
    """(path, pid, role) of staging and moved-aside directories of ``target`` left in its parent."""
    pat = re.compile(rf"^\.{re.escape(target.name)}\.(staging|old)-(\d+)$")
    try:
        names = os.listdir(target.parent)
    except OSError:
        return []
    return [(target.parent / n, int(m.group(2)), m.group(1)) for n in names if (m := pat.match(n))]


def recover(target) -> None:
    """Clean up after a writer of ``target`` that died: remove its staging directory; put back an
    old set it had moved aside if no new set reached the target, else remove that old set."""
    target = Path(target)
    for path, pid, role in sorted(_leftovers(target), key=lambda x: x[2] == "old"):
        if alive(pid):
            continue
        if role == "old" and not os.path.lexists(target):
            os.rename(path, target)
        elif path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:  # a staged file (an export, an output file)
            path.unlink(missing_ok=True)


_RENAME_EXCHANGE = 2


_AT_FDCWD = -100


def exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux renameat2 RENAME_EXCHANGE); False where not supported."""
    if os.environ.get("REPLAY_NO_EXCHANGE") == "1" or not sys.platform.startswith("linux"):
        return False
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False  # the kernel or the file system has no exchange
    raise OSError(err, os.strerror(err), str(b))


def publish_dir(staging, target) -> None:
    """Move the complete directory ``staging`` to ``target`` in one step, replacing what is there.

    The caller has checked that an existing ``target`` may be replaced (:func:`check_replaceable`)
    and that ``staging`` is beside it (same file system). Absent target: ``rename``. Existing:
    ``renameat2(RENAME_EXCHANGE)``, then the old set (now at the staging name) is removed; where
    exchange is not available, the old set is renamed aside to ``.<name>.old-<pid>``, the new one
    renamed in, the old one removed (a crash between the two renames is repaired by :func:`recover`
    on the next write, which puts the old set back). The parent directory is fsynced.
    """
    staging, target = Path(staging), Path(target)
    placed = False
    if not os.path.lexists(target):
        try:
            os.rename(staging, target)
            placed = True
        except OSError as e:  # created meanwhile by another writer: swap with it below
            if e.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                raise
    if not placed and exchange(staging, target):
        fault_point("swapped")
        shutil.rmtree(staging, ignore_errors=True)
    elif not placed:
        old = target.with_name(f".{target.name}.old-{os.getpid()}")
        os.rename(target, old)
        fault_point("aside")
        try:
            os.rename(staging, target)
        except OSError:
            os.rename(old, target)  # put the old set back before reporting the failure
            raise
        shutil.rmtree(old, ignore_errors=True)
    fsync_path(target.parent, directory=True)
