"""The kernel cache's directory and files: owner-only, written atomically, one note per problem.

What the cache trusts: the owner's own files. The directory is kept owner-only (0700, files
0600); one writable by others is made owner-only, one owned by another user is not used
(:func:`private_dir`). Nothing here knows numba; numba's files of the copies are sealed
with this user's key (:mod:`replay.util.kernel_cache`).
"""

from __future__ import annotations

import os
import stat
import uuid
from pathlib import Path

from replay.util.kernel_cache import CACHE_REPORT, cache_root, log, note_once, write_private  # noqa: F401


def cache_dir() -> Path:
    """``$REPLAY_CACHE_DIR/kernels`` (default ``~/.cache/replay/kernels``)."""
    return cache_root() / "kernels"


def private_dir(directory: Path) -> str | None:
    """Make ``directory`` (and its ``__pycache__``) an owner-only directory of this user:
    None when done, else why it cannot be used (one line naming the environment variable the
    cache's root ``directory.parent`` came from, or the directory)."""
    variable = next((v for v in ("REPLAY_CACHE_DIR", "XDG_CACHE_HOME") if os.environ.get(v)), None)
    if variable == "REPLAY_CACHE_DIR":
        where = f"{variable}={directory.parent}"
    else:
        where = f"kernel cache {directory}" + (f" (from {variable})" if variable else "")
    try:
        directory.mkdir(parents=True, exist_ok=True, mode=0o700)
        for d in (directory, directory / "__pycache__"):
            d.mkdir(mode=0o700, exist_ok=True)
            st = os.stat(d, follow_symlinks=False)
            if not stat.S_ISDIR(st.st_mode):
                return f"{where}: {d} is not a directory"
            if st.st_uid != os.getuid():
                return f"{where}: {d} belongs to another user"
            if st.st_mode & 0o077:
                os.chmod(d, 0o700)
                note_once(f"kernel cache {d}: was open to others; made owner-only (0700)")
        parent = os.stat(directory.parent)
        if parent.st_mode & 0o002 and not parent.st_mode & stat.S_ISVTX:
            return f"{where}: {directory.parent} is writable by anyone (no sticky bit)"
        probe = directory / f".probe.{os.getpid()}.{uuid.uuid4().hex[:8]}"
        probe.touch(mode=0o600)
        probe.unlink()
    except (FileExistsError, NotADirectoryError):
        culprit = next(
            (p for p in (directory / "__pycache__", directory, *directory.parents) if p.exists() and not p.is_dir()),
            directory,
        )
        return f"{where}: " + ("not a directory" if culprit == directory.parent else f"{culprit} is not a directory")
    except OSError as e:
        return f"{where}: {e.strerror or e} (read-only or not writable)"
    return None
