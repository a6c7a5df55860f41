"""Which adapter reads a plain file or directory: a ROS 2 bag directory, a lake-trial log by its
header, else the extension (:func:`adapter_for`)."""

from __future__ import annotations

from pathlib import Path

from replay.util.errors import ReplayError
from replay.util.regular import check_regular


ADAPTER_BY_SUFFIX = {".csv": "bohai-csv", ".bag": "bags", ".mcap": "bags", ".db3": "bags"}


def looks_like_path(text: str) -> bool:
    path = Path(text).expanduser()
    return path.suffix.lower() in ADAPTER_BY_SUFFIX or path.exists()


def adapter_for(path: Path) -> str:
    """The adapter for a plain file, by extension (a ROS 2 bag directory -> bags); a FIFO or a
    device is refused before anything reads it (it may never end)."""
    check_regular(path, "a dataset", dir_ok=True)
    if path.is_dir() and (path / "metadata.yaml").is_file():
        return "bags"
    if path.suffix.lower() in (".csv", ".tsv", ".txt") and _looks_like_lake_log(path):
        return "lake"
    try:
        return ADAPTER_BY_SUFFIX[path.suffix.lower()]
    except KeyError:
        known = ", ".join(sorted(ADAPTER_BY_SUFFIX))
        raise ReplayError(
            f"{path}: cannot tell the file format from its extension {path.suffix or '(none)'!r} (known: {known})"
        ) from None


def _looks_like_lake_log(path: Path) -> bool:
    """A text log whose first non-comment line names a depth column and a time column,
    or that starts with the lake-log banner (see README, 'Lake-trial logs')."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for _, line in zip(range(50), fh):
                if line.startswith("# replay lake-trial"):
                    return True
                if line.strip() and not line.startswith("#"):
                    cols = [c.strip().lower() for c in line.replace("\t", ",").split(",")]
                    return (
                        any(c.startswith("depth") for c in cols)
                        and any(c.startswith("time") for c in cols)
                        and not any(c.startswith(("lat", "lon")) for c in cols)
                    )
    except OSError:
        return False
    return False
