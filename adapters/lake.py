"""Lake-trial depth log adapter (``lake``), and its writer.

The format (also in README.md, "Lake-trial logs"): a CSV or TSV text file.

* Optional comment lines first, starting with ``#``. ``# key: value`` lines are
  kept in ``meta["header"]``; ``# units: depth=m, pitch=deg`` gives units of
  columns whose names carry none; ``# synthetic: true`` marks generated data.
* One header row, then one row per internal-sensor sample (any fixed or
  jittered rate): ``time`` (required), ``depth``, ``speed``, ``pitch`` and the
  reference's ``ref_time``, ``ref_depth``, ``ref_speed``, ``ref_pitch``, in any order,
  case-insensitive, the unit in the name (``pitch_deg``, ``pitch [deg]``) or in the
  ``units`` line; the table of columns and units is README.md's. Without ``ref_time``
  a reference cell belongs to the sensor time of its row. Empty cells are missing.

What :func:`load` does (everything counted in ``frame.report``):

* sensor rows need a finite, strictly increasing time (others are dropped and
  counted); ``inf`` cells are missing values (masked and counted per column);
  a few values outside plausible ranges (:data:`RANGES`) are masked;
* every declared unit is checked against the values (:mod:`replay.adapters.lake_units`): a
  median time step outside :data:`STEP_RANGE` (1 ms .. 10 s), a column mostly outside its
  kind's range, pitch in radians beyond pi/2, depth changes that do not match speed x
  sin(pitch) (``depth_cm`` holding metres), a sensor and its reference a factor apart: refused
  with the likely unit; pitch in degrees that never leaves +-0.5 deg is flagged;
* the reference is **aligned** to the sensor times without inventing samples:
  a sensor sample at a reference time takes it; between two reference samples
  at most ``max_gap`` seconds apart (default 0.5 s) it is linearly
  interpolated ("repaired"); inside a longer gap, or outside the reference's
  time span, it is masked. ``meta["reference_alignment"]`` holds the counts.
* ``Frame.columns`` names the column of each channel (``"reference depth"`` for the
  reference's), ``Frame.maneuvers`` the header's ``maneuvers`` segments (on ``t``),
  and ``Frame.default_task`` is ``depth``.

Bad input (no time column, unrecognised unit, a reference with no time
overlap, ...) raises :class:`replay.util.errors.DataError`: one line naming the
file and the column.
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pandas as pd

from replay.util.angles import wrap
from replay.util.errors import DataError, shown
from replay.adapters.lake_units import (
    RANGES,
    SI,
    STEP_RANGE,
    UNITS,
    check_range,  # noqa: F401
    check_step,
    check_units,
)
from replay.adapters.options import declare
from replay.frame import Channel, Frame, Report
from replay.util.params import Param

from replay.adapters.lake_align import MAX_GAP, align
from replay.adapters.lake_table import numeric, parse_column, read_table

FRAMES = {"depth": "down", "speed": "body forward", "pitch": "body"}
DESCRIPTION = {
    "depth": "depth gauge, positive down",
    "speed": "speed sensor, forward",
    "pitch": "pitch sensor, positive nose down",
}


# ---------------------------------------------------------------- columns


# ---------------------------------------------------------------- alignment


# ---------------------------------------------------------------- loading


@declare(
    "lake",
    Param(
        "max_gap",
        float,
        MAX_GAP,
        "longest reference gap bridged by linear interpolation",
        unit="s",
        low=0.0,
        low_open=True,
    ),
)
def load(path, *, max_gap) -> Frame:
    """Read a lake-trial depth log (module docstring) into a :class:`Frame`."""
    path = Path(path)
    table, comments, header, units_line, first_line = read_table(path)
    report = Report()
    cols = _columns(path, table, units_line, report)
    sensors = [k for k in ("depth", "speed", "pitch") if (False, k) in cols]
    rows = np.arange(len(table)) + first_line

    def si(ref, kind):
        col = cols[(ref, kind)]
        unit = parse_column(col, units_line)[2]
        v = numeric(path, table, col, first_line) * UNITS[kind][unit]
        if (inf := np.isinf(v)).any():
            report.add("masked", col, int(inf.sum()), f"infinite values (inf) at {_lines(rows, inf)}: missing")
        return np.where(inf, np.nan, v)

    time = si(False, "time")
    keep = _sensor_rows(path, table, cols, sensors, time, rows, report)
    t_abs = time[keep]
    t0 = float(t_abs[0])
    t = t_abs - t0
    unit = {key: parse_column(col, units_line)[2] for key, col in cols.items()}
    check_step(path, cols[(False, "time")], unit[(False, "time")], np.diff(t_abs))
    channels = {}
    for kind in sensors:
        channels[kind] = _channel(
            path,
            cols[(False, kind)],
            kind,
            unit[(False, kind)],
            si(False, kind)[keep],
            report,
            f"{DESCRIPTION[kind]} (column {cols[(False, kind)]})",
        )
    reference, alignment = {}, {}
    rt = si(True, "time") if (True, "time") in cols else np.where(keep, time, np.nan)
    for kind in [k for k in ("depth", "speed", "pitch") if (True, k) in cols]:
        reference[kind], alignment[kind] = _reference(
            path, cols[(True, kind)], kind, unit[(True, kind)], rt, si(True, kind), t_abs, max_gap, report
        )
    check_units(path, t, channels, reference, cols, unit, report)
    step = np.diff(t)
    meta = {
        "source": str(path),
        "adapter": "lake",
        "comments": comments,
        "header": header,
        "synthetic": header.get("synthetic", "").lower() in ("true", "yes", "1"),
        "time": {
            "offset": t0,
            "median_step": float(np.median(step)),
            "min_step": float(step.min()),
            "max_step": float(step.max()),
        },
        "reference_alignment": alignment,
        "pitch_convention": "pitch positive nose down",
    }
    columns = {("reference " if r else "") + k: (c,) for (r, k), c in cols.items()}
    maneuvers = _parse_maneuvers(header["maneuvers"], t0) if "maneuvers" in header else ()
    return Frame(t, channels, reference, None, meta, report, columns=columns, maneuvers=maneuvers, default_task="depth")


def _columns(path, table, units_line, report) -> dict[tuple[bool, str], str]:
    """{(reference?, kind): column} of the recognised columns (the others dropped, in the report);
    a time column and a sensor column required, every unit known."""
    cols: dict[tuple[bool, str], str] = {}
    for col in table.columns:
        parsed = parse_column(col, units_line)
        if parsed is None:
            report.add("dropped", col, len(table), "not a column of the lake-trial format")
            continue
        ref, kind, unit = parsed
        if (ref, kind) in cols:
            raise DataError(
                path, f"column {col}: a second {'reference ' if ref else ''}{kind} column (first: {cols[(ref, kind)]})"
            )
        if unit is None:
            raise DataError(
                path,
                f"column {col}: no unit (name it e.g. {kind}_{SI[kind].replace('/', 'p')} "
                f"or add '# units: {col}={SI[kind]}')",
            )
        if unit not in UNITS[kind]:
            raise DataError(
                path, f"column {col}: unit {shown(unit)} not recognised for {kind} (known: {', '.join(UNITS[kind])})"
            )
        cols[(ref, kind)] = col
    if (False, "time") not in cols:
        raise DataError(path, f"no time column (expected e.g. 'time_s'; columns: {', '.join(table.columns)})")
    if not any((False, k) in cols for k in ("depth", "speed", "pitch")):
        raise DataError(path, "no sensor column (depth, speed or pitch) besides the time")
    return cols


def _sensor_rows(path, table, cols, sensors, time, rows, report) -> np.ndarray:
    """The rows kept as sensor samples: with a time, strictly increasing (the others counted)."""
    has_time = np.isfinite(time)
    empty = [table[cols[(False, k)]].str.strip().str.lower().isin(["", "nan", "na", "null"]) for k in sensors]
    no_time = ~has_time & ~np.logical_and.reduce([e.to_numpy() for e in empty])
    if no_time.any():
        report.add(
            "dropped",
            "rows",
            int(no_time.sum()),
            f"sensor values without a time ({cols[(False, 'time')]}) at {_lines(rows, no_time)}",
        )
    keep = has_time.copy()
    running = -np.inf
    for i in np.flatnonzero(has_time):  # strictly increasing sensor time
        if time[i] <= running:
            keep[i] = False
        else:
            running = time[i]
    dropped = has_time & ~keep
    if dropped.any():
        report.add(
            "dropped",
            cols[(False, "time")],
            int(dropped.sum()),
            f"time not increasing (first at line {rows[np.argmax(dropped)]})",
        )
    if keep.sum() < 2:
        raise DataError(path, f"column {cols[(False, 'time')]}: fewer than 2 valid sensor times")
    return keep


def _reference(path, col, kind, unit, rt, vr, t_abs, max_gap, report) -> tuple[Channel, dict]:
    """A reference column on the sensor times (:func:`align`) and what the alignment did."""
    ok = np.isfinite(rt) & np.isfinite(vr)
    tr, vv = rt[ok], vr[ok]
    order = np.argsort(tr, kind="stable")
    tr, vv = tr[order], vv[order]
    dup = np.concatenate([[False], np.diff(tr) <= 0])
    if dup.any():
        report.add("dropped", col, int(dup.sum()), "repeated reference time")
        tr, vv = tr[~dup], vv[~dup]
    if len(tr) == 0:
        raise DataError(path, f"column {col}: no reference sample with a time")
    if tr[-1] < t_abs[0] or tr[0] > t_abs[-1]:
        raise DataError(
            path,
            f"column {col}: reference times {tr[0]:g}..{tr[-1]:g} s do not "
            f"overlap the sensor times {t_abs[0]:g}..{t_abs[-1]:g} s",
        )
    vv = check_range(path, col, kind, unit, vv, report)
    vals, valid, counts = align(t_abs, tr, vv, max_gap, angle=(kind == "pitch"))
    valid &= np.isfinite(vals)
    if counts["interpolated"]:
        report.add(
            "repaired",
            f"reference {kind}",
            counts["interpolated"],
            f"{col} interpolated linearly between reference samples at most {max_gap:g} s apart",
        )
    if counts["in_gaps"]:
        report.add(
            "masked",
            f"reference {kind}",
            counts["in_gaps"],
            f"{col}: {counts['gaps']} gap(s) longer than {max_gap:g} s",
        )
    if counts["outside"]:
        report.add(
            "masked", f"reference {kind}", counts["outside"], f"{col}: sensor samples outside the reference's time span"
        )
    return (
        Channel(
            vals,
            SI[kind],
            FRAMES[kind],
            valid,
            (kind,),
            (0,) if kind == "pitch" else (),
            "positive nose down" if kind == "pitch" else "",
            f"external reference {kind} (column {col})",
        ),
        dict(counts, column=col, max_gap=max_gap),
    )


def _lines(rows, mask, most=5) -> str:
    sel = np.asarray(rows)[np.asarray(mask)]
    more = " ..." if len(sel) > most else ""
    return ("line " if len(sel) == 1 else "lines ") + ", ".join(map(str, sel[:most])) + more


def _channel(path, col, kind, unit, v, report, description) -> Channel:
    missing = ~np.isfinite(v)
    if missing.any():
        report.add("masked", kind, int(missing.sum()), f"{col}: missing values (empty or infinite cells)")
    v = check_range(path, col, kind, unit, v, report)
    return Channel(
        v,
        SI[kind],
        FRAMES[kind],
        None,
        (kind,),
        (0,) if kind == "pitch" else (),
        "positive nose down" if kind == "pitch" else "",
        description,
    )


def _parse_maneuvers(text: str, t0: float) -> list[tuple]:
    out = []
    for item in text.split(";"):
        m = re.match(r"\s*([-\d.eE+]+)\s*-\s*([-\d.eE+]+)\s*(.*)$", item)
        if m:
            out.append((float(m.group(1)) - t0, float(m.group(2)) - t0, m.group(3).strip()))
    return out


# ---------------------------------------------------------------- writing
