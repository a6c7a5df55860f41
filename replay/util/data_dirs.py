"""Where datasets are looked for and kept: the user cache, the search roots, a ``data_dir`` checked.

Plain path helpers (a leaf: nothing of replay but its errors), re-exported by
:mod:`replay.data.registry`.
"""

from __future__ import annotations

import os
from pathlib import Path

from replay.util.errors import ReplayError


def cache_dir() -> Path:
    """The user cache: $REPLAY_CACHE_DIR, else $XDG_CACHE_HOME/replay, else ~/.cache/replay."""
    if os.environ.get("REPLAY_CACHE_DIR"):
        return Path(os.environ["REPLAY_CACHE_DIR"]).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "replay"


def cache_variable() -> str | None:
    """The environment variable the user cache comes from (REPLAY_CACHE_DIR, XDG_CACHE_HOME), if any:
    named in refusals about the cache's directory."""
    return next((v for v in ("REPLAY_CACHE_DIR", "XDG_CACHE_HOME") if os.environ.get(v)), None)


def search_roots(data_dir: str | Path | None = None) -> list[Path]:
    """The directories searched, in order: data_dir, $REPLAY_DATA_DIR, the user cache."""
    roots = [Path(data_dir).expanduser()] if data_dir else []
    env = os.environ.get("REPLAY_DATA_DIR", "")
    roots += [Path(p).expanduser() for p in env.split(os.pathsep) if p]
    roots.append(cache_dir())
    return list(dict.fromkeys(roots))


def check_data_dir(data_dir, what: str = "data_dir") -> None:
    """Refuse, in one line, a ``data_dir`` that is given but is not a directory (for every dataset,
    simulated ones too: a mistyped path is never silently ignored)."""
    if data_dir is None:
        return
    if not isinstance(data_dir, (str, os.PathLike)) or not str(data_dir):
        raise ReplayError(f"{what} {data_dir!r}: expected the path of a directory")
    p = Path(data_dir).expanduser()
    if not p.exists():
        raise ReplayError(f"{what} {data_dir}: no such directory")
    if not p.is_dir():
        raise ReplayError(f"{what} {data_dir}: is a file, not a directory")
