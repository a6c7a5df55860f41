"""A lake-trial log's text: comment lines, the table, its columns and their units (:mod:`replay.adapters.lake`)."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pandas as pd

from replay.util.errors import DataError, shown


KINDS = {
    "time": "time",
    "t": "time",
    "timestamp": "time",
    "depth": "depth",
    "speed": "speed",
    "velocity": "speed",
    "pitch": "pitch",
}
REF_PREFIXES = ("ref_", "ref.", "ref ", "reference_", "ext_", "external_")


def parse_column(name: str, units_line: dict):
    """(is_reference, kind, unit) of a column name, or None when it is not a known column."""
    low = name.strip().lower()
    unit = None
    m = re.match(r"^(.*?)\s*[\[(](.+?)[\])]\s*$", low)
    if m:
        low, unit = m.group(1).strip(), m.group(2).strip()
    ref = low.startswith(REF_PREFIXES)
    base = low
    for p in REF_PREFIXES:
        if base.startswith(p):
            base = base[len(p) :]
            break
    kind = KINDS.get(base)
    if kind is None and unit is None and "_" in base:
        head, _, tail = base.partition("_")
        if head in KINDS:
            kind, unit = KINDS[head], tail
    if kind is None:
        return None
    key = ("ref_" if ref else "") + kind
    if unit is None:
        unit = units_line.get(key) or units_line.get(kind)
    return ref, kind, unit


def _comments(path, text: str):
    lines = text.splitlines()
    comments, i = [], 0
    while i < len(lines) and (lines[i].lstrip().startswith("#") or not lines[i].strip()):
        if lines[i].strip():
            comments.append(lines[i].lstrip()[1:].strip())
        i += 1
    header, units = {}, {}
    for c in comments:
        key, sep, value = c.partition(":")
        if sep and key.strip() and " " not in key.strip():
            header[key.strip().lower()] = value.strip()
    for item in re.split(r"[,;]", header.get("units", "")):
        k, sep, v = item.partition("=")
        if sep:
            units[k.strip().lower()] = v.strip().lower()
    return comments, header, units, i


def read_table(path: Path):
    if not path.is_file():
        raise DataError(path, "file not found")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as err:
        raise DataError(path, f"cannot read as text: {err}") from None
    comments, header, units, skip = _comments(path, text)
    body = text.splitlines()[skip:]
    if not body:
        raise DataError(path, "no header row (expected e.g. time_s,depth_m,speed_mps,pitch_deg,ref_depth_m)")
    sep = "\t" if "\t" in body[0] else ("," if "," in body[0] else (";" if ";" in body[0] else ","))
    try:
        table = pd.read_csv(
            io.StringIO("\n".join(body)), sep=sep, dtype=str, skip_blank_lines=True, keep_default_na=False
        )
    except (pd.errors.ParserError, ValueError) as err:
        raise DataError(
            path, f"not a readable {'TSV' if sep == chr(9) else 'CSV'} table: {str(err).strip().splitlines()[-1]}"
        ) from None
    table.columns = [str(c).strip() for c in table.columns]
    if len(table) == 0:
        raise DataError(path, "header only, no data rows")
    return table, comments, header, units, skip + 2  # file line of the first data row


def numeric(path, table, col, first_line) -> np.ndarray:
    s = table[col].str.strip()
    s = s.where(~s.str.lower().isin(["", "nan", "na", "null"]), None)
    num = pd.to_numeric(s, errors="coerce")
    bad = num.isna().to_numpy() & s.notna().to_numpy()
    if bad.any():
        i = int(np.argmax(bad))
        raise DataError(path, f"column {col}: non-numeric value {shown(table[col].iloc[i])}", row=first_line + i)
    return num.to_numpy(dtype=float)
