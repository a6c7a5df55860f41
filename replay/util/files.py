"""Writing output files so that a crash leaves the old file or the new one, never a mix."""
from __future__ import annotations

import csv
import os
from io import StringIO
from pathlib import Path


def write_atomic(path, text: str) -> None:
    """Write ``text`` to a temporary file beside ``path`` and rename it into place (atomic)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def fmt(v) -> str:
    """A CSV cell: floats with 6 significant digits ("nan" for non-finite), the rest as text."""
    if isinstance(v, float):
        return f"{v:.6g}" if v == v and v not in (float("inf"), float("-inf")) else "nan"
    return str(v)


def write_csv(rows: list[dict], path, columns: list[str]) -> None:
    """``rows`` as a CSV file with ``columns`` (missing cells empty), written atomically."""
    buf = StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: fmt(v) for k, v in row.items()})
    write_atomic(path, buf.getvalue())
