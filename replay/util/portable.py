"""Documents meant for users hold no machine-specific path: :func:`check_portable`, :func:`write_document`.

A reproduction document, a report or a README fragment written by a command must read the same on
every machine: no home directory, temporary directory, cache directory or checkout location in it.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from replay.util.files import write_atomic


def _machine_paths() -> list[str]:
    out = {str(Path.home()), tempfile.gettempdir(), str(Path.cwd()), str(Path(__file__).resolve().parents[2])}
    out |= {os.environ.get(k, "") for k in ("TMPDIR", "HOME", "REPLAY_CACHE_DIR")}
    return sorted((p for p in out if p and p not in ("/", ".")), key=len, reverse=True)


def check_portable(text: str, where: str) -> None:
    """Refuse text holding a machine-specific path (a home, a temp dir, the checkout's location)."""
    for p in _machine_paths():
        if p in text:
            raise ValueError(
                f"{where}: holds the machine-specific path {p!r}; write it relative to the repository or as a command"
            )


def write_document(path, text: str) -> Path:
    """Check ``text`` is portable and write it to ``path`` atomically."""
    path = Path(path)
    check_portable(text, str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, text)
    return path
