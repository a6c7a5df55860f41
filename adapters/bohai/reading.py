"""Reading a Bohai CSV: bytes, the numeric table, its layout, clean rows, the time axis.

Also the two report helpers every stage uses: :func:`_rows` (``lines 4, 9, 12``)
and :func:`_drop` (a column not passed on).
"""

from __future__ import annotations

import csv
import hashlib
import io
import re
from pathlib import Path

import numpy as np
import pandas as pd

from replay.util.errors import DataError, shown

from .columns import COLS31, COLS36


def _drop(report, meta, column, count, reason):
    meta["dropped_columns"][column] = reason
    report.add("dropped", column, count, reason)


class _Hashing(io.RawIOBase):
    """A binary file read through a SHA-256: what the parser reads is what is hashed."""

    def __init__(self, fh):
        self.fh, self.sha = fh, hashlib.sha256()

    def readable(self) -> bool:
        return True

    def readinto(self, buf) -> int:
        n = self.fh.readinto(buf)
        if n:
            self.sha.update(memoryview(buf)[:n])
        return n


def _read(path: Path):
    """The table (:func:`_parse`), its line numbers and the SHA-256 of the file. The bytes stream
    through the hash into the parser: the file is never held whole in memory beside the table."""
    if not path.exists():
        raise DataError(path, "file not found")
    if not path.is_file():
        raise DataError(path, "not a file")
    try:
        with open(path, "rb") as fh:
            first, seen = _first_line(fh)
            blank = not seen.strip()
            while blank and (chunk := fh.read(1 << 20)):  # up to the first non-blank byte
                blank = not chunk.strip()
        if blank:
            raise DataError(path, "file is empty")
        with open(path, "rb", buffering=0) as fh:
            stream = _Hashing(fh)
            table, lines = _parse(path, io.BufferedReader(stream, 1 << 20), first)
            while stream.read(1 << 20):  # the rest, if the parser stopped short of the end
                pass
    except OSError as err:
        raise DataError(path, f"cannot read: {err.strerror or err}") from None
    return table, lines, stream.sha.hexdigest()


def _first_line(fh, chunk: int = 1 << 16) -> tuple[bytes, bytes]:
    """(the first line, every byte read) of a binary file: a line ends at LF, CRLF or a lone CR
    (old Mac files, where one ``readline`` would be the whole file)."""
    head = b""
    while block := fh.read(chunk):
        head += block
        end = re.search(rb"[\r\n]", block)
        if end:
            return head[: len(head) - len(block) + end.start()], head
    return head, head


def _parse(path, source, first: bytes):
    """The table as floats and, per row, its 1-based line number in the file (``first``: its first line)."""
    try:
        table = pd.read_csv(source, skip_blank_lines=False, encoding="utf-8-sig")
    except pd.errors.EmptyDataError:
        raise DataError(path, "file is empty") from None
    except pd.errors.ParserError as err:
        last = str(err).strip().splitlines()[-1]
        line = re.search(r"line (\d+)", last)
        raise DataError(path, f"not a readable CSV table: {last}", row=int(line.group(1)) if line else None) from None
    except (UnicodeDecodeError, ValueError) as err:
        raise DataError(path, f"not a readable CSV table: {err}") from None
    table.columns = [str(c).strip() for c in table.columns]
    header = next(csv.reader([first.decode("utf-8-sig", errors="replace")]), [])
    header = [c.strip() for c in header]  # (pandas renames a repeated name to NAME.1)
    twice = [c for i, c in enumerate(header) if c in header[:i]]
    if twice:
        raise DataError(path, f"column {shown(twice[0])} appears twice in the header", row=1)
    if len(table) == 0:
        raise DataError(path, "header only, no data rows")
    lines = np.arange(len(table)) + 2  # header is line 1; blank lines stay rows
    bad_at = None
    for c in table.columns:
        col = table[c]
        if col.dtype.kind in "fiub":
            continue
        num = pd.to_numeric(col.astype(str).str.strip().replace({"nan": ""}).replace("", np.nan), errors="coerce")
        bad = num.isna().to_numpy() & col.notna().to_numpy()
        if bad.any():
            i = int(np.argmax(bad))
            if bad_at is None or i < bad_at[0]:
                bad_at = (i, c, col.iloc[i])
        table[c] = num
    if bad_at is not None:
        i, c, v = bad_at
        raise DataError(path, f"non-numeric value {shown(str(v))} in column {c}", row=int(lines[i]))
    return table.astype(float), lines


def _layout(path, columns) -> int:
    have = set(columns)
    missing = {36: [c for c in COLS36 if c not in have], 31: [c for c in COLS31 if c not in have]}
    for layout in (36, 31):
        if not missing[layout]:
            return layout
    near = min(missing, key=lambda k: len(missing[k]))
    raise DataError(
        path,
        f"header matches neither Bohai layout: missing columns "
        f"{', '.join(missing[near])} (of the {near}-column layout)",
    )


def _rows(lines, mask, most=5) -> str:
    """'lines 4, 9, 12' for the first few rows in ``mask``."""
    sel = np.asarray(lines)[np.asarray(mask)]
    text = ", ".join(str(int(r)) for r in sel[:most])
    return ("line " if len(sel) == 1 else "lines ") + text + (" ..." if len(sel) > most else "")


def _clean_rows(path, table, names, lines, report, meta):
    """Drop empty rows, rows without time and exact duplicates; fail on other time problems.

    Returns the layout's columns (name -> float array) and the kept rows' line numbers.
    """
    n_read = len(lines)
    empty = np.ones(n_read, bool)
    for j in range(table.shape[1]):  # column by column: no table-sized temporary
        empty &= table.iloc[:, j].isna().to_numpy()
    names = list(names)
    values = np.empty((n_read, len(names)))  # one copy of the layout's columns, row-major
    for j, c in enumerate(names):
        values[:, j] = table[c].to_numpy(dtype=float)
    if empty.any():
        report.add("dropped", "rows", int(empty.sum()), f"empty or all-NaN rows at {_rows(lines, empty)}")
    no_time = ~empty & ~np.isfinite(values[:, names.index("time")])
    if no_time.any():
        report.add("dropped", "rows", int(no_time.sum()), f"no time value at {_rows(lines, no_time)}")
    keep = ~empty & ~no_time
    if not keep.all():
        values, lines = values[keep], lines[keep]
    if len(lines) == 0:
        raise DataError(path, "no data rows with a time value")
    time = values[:, names.index("time")]
    same = np.r_[False, np.diff(time) == 0]
    if same.any():
        prev = np.r_[values[:1], values[:-1]]
        identical = same & ((values == prev) | (np.isnan(values) & np.isnan(prev))).all(axis=1)
        if (same & ~identical).any():
            i = int(np.argmax(same & ~identical))
            raise DataError(
                path,
                f"time {time[i]:g} s repeats line {lines[i - 1]} with different values (duplicate timestamp)",
                row=int(lines[i]),
            )
        report.add(
            "dropped",
            "rows",
            int(identical.sum()),
            f"exact duplicates of the previous row at {_rows(lines, identical)}",
        )
        values, lines, time = values[~identical], lines[~identical], time[~identical]
    back = np.diff(time) < 0
    if back.any():
        i = int(np.argmax(back)) + 1
        raise DataError(
            path, f"time decreases from {time[i - 1]:g} s (line {lines[i - 1]}) to {time[i]:g} s", row=int(lines[i])
        )
    if len(lines) < 2:
        raise DataError(path, "fewer than 2 usable data rows")
    meta["rows"] = {"read": n_read, "kept": len(lines), "dropped": n_read - len(lines)}
    return {c: values[:, j] for j, c in enumerate(names)}, lines


def _time_axis(t, lines, report, gap_factor) -> dict:
    dt = np.diff(t)
    med = float(np.median(dt))
    gaps = dt > gap_factor * med
    stats = {
        "median_step": med,
        "min_step": float(dt.min()),
        "max_step": float(dt.max()),
        "span": float(t[-1]),
        "gaps": int(gaps.sum()),
    }
    report.add(
        "info",
        "time",
        len(t),
        f"median step {med:.4f} s, min {dt.min():.4f} s, max {dt.max():.4f} s, span {t[-1]:.1f} s",
    )
    if gaps.any():
        i = int(np.argmax(dt))
        report.add(
            "flagged",
            "time",
            int(gaps.sum()),
            f"gaps > {gap_factor:g} x median step (longest {dt[i]:.3f} s before line {lines[i + 1]})",
        )
    return stats
