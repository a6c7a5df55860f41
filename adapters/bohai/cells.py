"""Bad cells and the time unit of a Bohai CSV: repaired or refused, and counted in the report.

* :func:`mask_infinite`: ``inf`` / ``-inf`` cells are missing values (NaN), counted per
  column; a column is never dropped for a few of them.
* :func:`mask_isolated`: a few cells beyond the magnitude limit of their column's kind
  (at most :data:`ISOLATED_SHARE` of its values) are masked and counted; a column with
  more is garbage and the per-column checks drop it (the upstream quirks: ``vn`` etc.
  exceed their limit in 6-100 % of the rows).
* :func:`time_unit`: the format's ``time`` is seconds at about 10 Hz. A median step
  outside [:data:`STEP_RANGE`] s is not seconds: if dividing by 1e3, 1e6 or 1e9 gives a
  plausible step and a plausible position-derived speed, the column is converted
  ("repaired", every row counted); otherwise one line refuses the file.
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import DataError

from .columns import COLUMNS, LIMITS
from .reading import _rows

ISOLATED_SHARE = 0.01  # at most this share of a column's values beyond its limit: masked, not dropped
STEP_RANGE = (0.02, 1.0)  # s: plausible median sample step (the logs are about 10 Hz)
NOMINAL_RATE_STEP = 0.1  # s
UNITS = ((1e-3, "milliseconds"), (1e-6, "microseconds"), (1e-9, "nanoseconds"))
EARTH_M_PER_DEG = 111_320.0


def mask_infinite(table, lines, report):
    """Infinite cells as NaN (the table is changed in place), one "masked" entry per column."""
    for j, c in enumerate(table.columns):  # column by column: no table-sized temporary
        x = table.iloc[:, j].to_numpy(dtype=float)
        bad = np.isinf(x)
        if bad.any():
            report.add("masked", c, int(bad.sum()), f"infinite values (inf) at {_rows(lines, bad)}: treated as missing")
            table.isetitem(j, np.where(bad, np.nan, x))


def mask_isolated(cols, lines, report):
    """Mask the few cells beyond their kind's magnitude limit (module docstring); ``cols`` changed in place."""
    for c, x in cols.items():
        if c not in COLUMNS or COLUMNS[c][0] not in LIMITS:
            continue
        limit, unit = LIMITS[COLUMNS[c][0]]
        over = np.abs(x) > limit
        k = int(over.sum())
        if 0 < k <= ISOLATED_SHARE * np.isfinite(x).sum():
            report.add(
                "masked",
                c,
                k,
                f"|value| beyond the {limit:g} {unit} limit at "
                f"{_rows(lines, over)} (isolated: at most "
                f"{ISOLATED_SHARE:.0%} of the column)",
            )
            cols[c] = np.where(over, np.nan, x)


def _median_speed(lat, lon, dt_steps):
    """Median position-derived speed (m per time unit) over steps between plausible samples."""
    ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
    both = ok[1:] & ok[:-1] & (dt_steps > 0)
    if both.sum() < 10:
        return None
    dlat = np.diff(lat)[both] * EARTH_M_PER_DEG
    dlon = np.diff(lon)[both] * EARTH_M_PER_DEG * np.cos(np.deg2rad(np.nanmedian(lat[ok])))
    return float(np.median(np.hypot(dlat, dlon) / dt_steps[both]))


def time_unit(path, time, cols, lines, report, meta, max_speed):
    """``time`` in seconds: unchanged, converted (with a report line), or DataError (module docstring)."""
    steps = np.diff(time)
    med = float(np.median(steps))
    lo, hi = STEP_RANGE
    if lo <= med <= hi:
        meta["time_unit"] = {"unit": "seconds", "factor": 1.0}
        if not 0.5 * NOMINAL_RATE_STEP <= med <= 2 * NOMINAL_RATE_STEP:
            report.add(
                "flagged",
                "time",
                len(time),
                f"median step {med:.4g} s: the Bohai logs are about {1 / NOMINAL_RATE_STEP:g} Hz",
            )
        return time
    speed = _median_speed(cols["lat"], cols["lon"], steps)
    for factor, unit in UNITS:
        if not lo <= med * factor <= hi:
            continue
        v = None if speed is None else speed / factor
        if v is not None and v > max_speed:
            raise DataError(
                path,
                f"column time: median step {med:g} is not seconds; read as {unit} "
                f"({med * factor:.4g} s) the vehicle would move at {v:.1f} m/s, above the "
                f"{max_speed:g} m/s limit: fix the time column",
            )
        why = "" if v is None else (f"; position-derived median speed then {v:.2f} m/s instead of {speed:.3g} m/s")
        report.add(
            "repaired",
            "time",
            len(time),
            f"time column in {unit}: median step {med:g} is implausible as seconds for a ~10 Hz "
            f"log, {med * factor:.4g} s as {unit}; divided by {1 / factor:g}{why}",
        )
        meta["time_unit"] = {"unit": unit, "factor": factor, "median_step_raw": med}
        return time * factor
    raise DataError(
        path,
        f"column time: median step {med:g} is implausible for a ~10 Hz log in seconds "
        f"(expected {lo:g}-{hi:g} s), and as milliseconds, microseconds or nanoseconds too",
    )
