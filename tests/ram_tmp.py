"""The test session's temporary directory in memory (``/dev/shm``) when the machine has one.

The tests write and fsync thousands of small files (run directories, campaign stores, Optuna's
SQLite studies); on a disk shared with other work that is most of some tests' time, in memory
almost nothing. ``TMPDIR`` is set before anything asks for the temporary directory, so pytest's
``tmp_path``, ``tempfile`` and subprocesses all use it, and a temporary path written into a
document is still caught as machine-specific (``replay.reproduce.verdict``). Not done when
``TMPDIR`` is already set, when ``REPLAY_TEST_RAM_TMP=0``, or when ``/dev/shm`` is not a tmpfs
with :data:`MIN_FREE` bytes free.
"""
from __future__ import annotations

import os
import tempfile

MIN_FREE = 2 << 30  # bytes free in /dev/shm


def _tmpfs(path: str) -> bool:
    try:
        with open("/proc/mounts", encoding="utf-8") as fh:
            mounts = [line.split() for line in fh]
        st = os.statvfs(path)
    except OSError:
        return False
    kind = max((m for m in mounts if len(m) > 2 and (path == m[1] or path.startswith(m[1].rstrip("/") + "/"))),
               key=lambda m: len(m[1]), default=None)
    return kind is not None and kind[2] == "tmpfs" and st.f_bavail * st.f_frsize >= MIN_FREE


def use_ram_tmpdir(root: str = "/dev/shm") -> str | None:
    """Set ``TMPDIR`` to ``<root>/replay-tests-<uid>`` (owner-only) and return it, or None when not done."""
    if os.environ.get("TMPDIR") or os.environ.get("REPLAY_TEST_RAM_TMP") == "0" or not _tmpfs(root):
        return None
    path = os.path.join(root, f"replay-tests-{os.getuid()}")
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
        st = os.stat(path, follow_symlinks=False)
        if not os.path.isdir(path) or os.path.islink(path) or st.st_uid != os.getuid():
            return None
        os.chmod(path, 0o700)
    except OSError:
        return None
    os.environ["TMPDIR"] = path
    tempfile.tempdir = None  # asked again: now TMPDIR
    return path
