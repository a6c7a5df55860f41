"""A unit record's own checksum, and the check of records written before it.

**Sealed records.** :func:`seal` stores in each record ``record_sha256``: the SHA-256
of the record's canonical JSON (keys sorted, no spaces, the record without that key,
after one JSON round trip so that tuples, numpy numbers and floats are what a reader
gets back). :func:`problem` recomputes it when the record is read: a changed digit
of a metric, a changed status, run or table checksum makes the unit damaged
(``campaign run`` computes it again and names it; ``leaderboard`` and ``report``
refuse naming the file). The record holds the table's SHA-256, so the checksum
covers the table too. It detects damage and edits, not a forger who recomputes it.

**Records without the checksum** (written by replay before it sealed them) are still
read. Their metrics that the verified per-step table determines are recomputed from
it and must agree (relative 1e-9; :func:`legacy_problem`): ``pos_rmse`` (the rows
whose position errors are all finite; the position axes are those with a ``ref_``
column), each ``<axis>_rmse`` and ``<angle>_rmse`` with an ``err_`` column,
``scored``, ``final_err``, and the mean ``nees`` and ``nis``. The others (``ate``,
``drift_pct``, ``diverged``, ``lost``, timings) are not in the table and are read
as recorded; ``replay campaign run --retry-failed`` does not reseal them (delete
the configuration's directory to recompute it with a checksum).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from replay.scoring.record import RunRecord
from replay.util import sealed

KEY = "record_sha256"
RTOL = 1e-9


def canonical(record: dict) -> bytes:
    """The bytes the checksum covers: the record without :data:`KEY`, keys sorted, compact."""
    return sealed.canonical(record, KEY)


def seal(record: dict, default) -> dict:
    """The record as a reader gets it back (one JSON round trip, ``default`` for numpy values)
    with its checksum."""
    plain = json.loads(json.dumps(record, default=default))
    plain[KEY] = sealed.digest(plain, KEY)
    return plain


def problem(path: Path, record: dict) -> str | None:
    """None when the record is intact or has no checksum, else one line naming ``path``."""
    if KEY not in record:
        return None
    if record[KEY] != sealed.digest(record, KEY):
        return f"{path}: content differs from the checksum it holds (record edited or damaged)"
    return None


def legacy_problem(path: Path, record: RunRecord, read) -> str | None:
    """For a done record without a checksum: a metric that disagrees with the table, as one line
    naming ``path``; ``read(columns)`` gives the table's columns (called once)."""
    if record.record_sha256 is not None or not record.done:
        return None
    names = read(None)
    m = record.metrics or {}
    axes = [k[4:] for k in names if k.startswith("ref_") and f"err_{k[4:]}" in names]
    with np.errstate(all="ignore"):
        pos = np.column_stack([names[f"err_{a}"] for a in axes]) if axes else np.zeros((0, 0))
        ok = np.isfinite(pos).all(axis=1) if axes else np.zeros(0, bool)
        e = pos[ok]
        found = {"scored": float(ok.sum())} if axes else {}
        if axes:
            found["pos_rmse"] = float(np.sqrt(np.mean(np.sum(e**2, axis=1)))) if len(e) else np.nan
            last = np.flatnonzero(ok)
            found["final_err"] = float(np.linalg.norm(pos[last[-1]])) if len(last) else np.nan
        for k, v in names.items():
            if k.startswith("err_"):
                a = np.asarray(v, float)
                a = a[np.isfinite(a)]
                found[f"{k[4:]}_rmse"] = float(np.sqrt(np.mean(a**2))) if len(a) else np.nan
        for k in ("nees", "nis"):
            if k in names:
                v = np.asarray(names[k], float)
                found[k] = float(np.nanmean(v)) if np.isfinite(v).any() else np.nan
    for key, value in found.items():
        if key not in m:
            continue
        try:
            given = float(m[key]) if m[key] is not None else np.nan
        except (TypeError, ValueError):
            return f"{path}: {key} is {m[key]!r}, not a number"
        same = (np.isnan(given) and np.isnan(value)) or np.isclose(given, value, rtol=RTOL, atol=0)
        if not same:
            return f"{path}: {key} {given!r} disagrees with its table ({value!r}); the record was edited or damaged"
    return None
