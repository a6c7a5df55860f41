"""Writing output files so that a crash leaves the old file or the new one, never a mix."""

from __future__ import annotations

import csv
import json
import os
from io import StringIO
from pathlib import Path

import numpy as np
from replay.util.errors import ReplayError


def write_atomic(path, text: str) -> None:
    """``text`` (UTF-8) into ``path`` atomically, not flushed to disk (:func:`write_bytes`)."""
    write_bytes(path, text.encode("utf-8"), sync=False)


def sync_dir(d: Path) -> None:
    """Flush a directory's entries (new names, renames) to disk."""
    try:
        fd = os.open(d, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_bytes(path, data: bytes, sync: bool = True) -> None:
    """``data`` into ``path``: a temporary file beside it, flushed to disk (``sync``), then an
    atomic rename; a symbolic link keeps its link and its target is replaced (as
    :func:`replay.util.outfile.write`)."""
    path = Path(os.path.realpath(path)) if os.path.islink(path) else Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            if sync:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:  # a full disk, an interruption: no partial temporary left behind
        tmp.unlink(missing_ok=True)
        raise


def write_json(path: Path, obj) -> None:
    write_bytes(path, json.dumps(obj, indent=1, default=json_default).encode())


def json_default(v):
    """A JSON value for numpy scalars and arrays (their Python values), anything else as text."""
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def fmt(v) -> str:
    """A CSV cell: floats in full (the shortest text that reads back as the same float; "nan" for
    non-finite), the rest as text."""
    if isinstance(v, float):
        return repr(v) if v == v and v not in (float("inf"), float("-inf")) else "nan"
    return str(v)


def csv_text(rows: list[dict], columns: list[str]) -> str:
    """``rows`` as CSV text with ``columns`` (missing cells empty, cells by :func:`fmt`)."""
    buf = StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: fmt(v) for k, v in row.items()})
    return buf.getvalue()


def write_csv(rows: list[dict], path, columns: list[str]) -> None:
    """``rows`` as a CSV file with ``columns`` (missing cells empty), written atomically."""
    write_atomic(path, csv_text(rows, columns))


def refuse_overlap(out, inputs, what: str = "output") -> Path:
    """Refuse an output path that equals, contains or lies inside one of ``inputs``.

    ``inputs`` are paths this command reads (files or directories; ``None`` entries are
    skipped). Paths are compared after resolving symbolic links, so a link to an input
    is the input. Returns the resolved output path. Raises :class:`ReplayError` with one
    line naming both paths.
    """
    target = Path(out).resolve()
    for src in inputs:
        if src is None:
            continue
        s = Path(src).resolve()
        if target == s:
            raise ReplayError(f"{what} {out}: is an input of this command; refusing to overwrite it")
        if s.is_relative_to(target):
            raise ReplayError(f"{what} {out}: contains the input {src}; refusing to replace it")
        if target.is_relative_to(s) and s.is_dir():
            raise ReplayError(f"{what} {out}: lies inside the input {src}; refusing to write there")
    return target


def check_writable(out, what: str = "output") -> None:
    """Refuse, before any computation, an output whose nearest existing parent is not writable."""
    p = Path(out).resolve()
    probe = p if p.exists() else next((q for q in p.parents if q.exists()), None)
    if probe is not None and probe.exists() and not probe.is_dir():
        if p == probe:
            probe = p.parent
        else:
            raise ReplayError(f"{what} {out}: {shown(out, probe)} is a file, not a directory")
    if probe is None or not os.access(probe, os.W_OK | os.X_OK):
        raise ReplayError(f"{what} {out}: {shown(out, probe)} is not writable")


def shown(out, probe):
    """``probe`` (an ancestor of the resolved ``out``) as the user wrote it, where it is one of
    the ancestors of ``out`` as given (no absolute path the user did not type)."""
    if probe is None:
        return probe
    for q in (Path(out), *Path(out).parents):
        if str(q) not in ("", ".") and q.resolve() == probe:
            return q
    return probe
