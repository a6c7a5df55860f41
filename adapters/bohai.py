"""Bohai AUV navigation CSV adapter (``bohai-csv``).

Reads the CSV logs of Wang et al., "Underwater AUV navigation dataset in
natural scenarios", Electronics 12(18):3788 (2023), CC0, in either header
layout (see the README beside the data, ``datasets/bohai/README.md`` in the
shared data directory):

* 36 columns: ``lat_gps, lon_gps, alt_gps, roll, ..., lat, lon, depth, height,
  time, time_gps`` (GPS fix columns apart from the navigation solution);
* 31 columns: ``lat, lon, alt, roll, ..., orimode, time``.

What the returned :class:`~replay.frame.Frame` holds:

* ``t``: ``time - time[0]`` (s); ``epoch`` is None (no trusted date in the
  files). A ``time_gps`` column that decodes as a GPS time of day (hhmmss) is
  recorded in ``meta["gps_time_of_day"]``, nothing more.
* ``reference["position"]``: (n, 2) east/north in m, local ENU = UTM - origin,
  from the navigation solution ``lat``/``lon``. Masked where lat/lon is
  missing or impossible, where fresh GPS fixes contradict it (see
  :func:`gps_contradiction`) and at the jumps of the navigation solution (see
  :func:`mask_jumps`). The navigation solution is dead reckoning between GPS
  corrections: unmasked samples in a dive still carry its drift.
* ``channels``: ``attitude`` (roll, pitch, yaw), ``gyro`` (wx, wy, wz),
  ``gps_position`` and ``gps_alt`` (36 columns) or ``alt`` (31 columns), and
  every other column that passes the plausibility checks (named after the
  column). A column that fails is not passed on: ``frame.report`` holds a
  "dropped" entry with the finding and ``meta["dropped_columns"]`` maps the
  column to the same reason.
* ``meta``: source, sha256, layout, adapter, crs, epsg, origin, rows, time,
  jumps, speed, yaw_course, gyro_attitude, dropped_columns; gps (36 columns);
  gps_time_of_day when ``time_gps`` holds one.

Bad input raises :class:`~replay.util.errors.DataError` with one line naming the
file and, where it applies, the file line (header = line 1).
"""
from __future__ import annotations

import hashlib
import io
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pyproj

from replay.util.angles import wrap
from replay.util.errors import DataError
from replay.frame import Channel, Frame, Report

COLS36 = ("lat_gps", "lon_gps", "alt_gps", "roll", "pitch", "yaw", "vn", "ve", "vf", "vl", "vu",
          "ax", "ay", "az", "af", "al", "au", "wx", "wy", "wz", "wf", "wl", "wu",
          "pos_accuracy", "vel_accuracy", "navstat", "numsats", "posmode", "velmode", "orimode",
          "lat", "lon", "depth", "height", "time", "time_gps")
COLS31 = ("lat", "lon", "alt", "roll", "pitch", "yaw", "vn", "ve", "vf", "vl", "vu",
          "ax", "ay", "az", "af", "al", "au", "wx", "wy", "wz", "wf", "wl", "wu",
          "pos_accuracy", "vel_accuracy", "navstat", "numsats", "posmode", "velmode", "orimode",
          "time")

NOMINAL_STEP = 0.1  # s: the logs are about 10 Hz; jump_threshold is per such step

# column -> (kind, unit, frame, description). Kinds select the plausibility checks.
COLUMNS = {
    "alt_gps": ("altitude", "m", "up", "GPS altitude"),
    "alt": ("altitude", "m", "up", "altitude"),
    "roll": ("roll", "rad", "body", "roll, positive = left side up"),
    "pitch": ("pitch", "rad", "body", "pitch, positive = front down"),
    "yaw": ("yaw", "rad", "ENU", "heading, 0 = east, counter-clockwise positive"),
    "vn": ("velocity", "m/s", "ENU", "north velocity"),
    "ve": ("velocity", "m/s", "ENU", "east velocity"),
    "vu": ("velocity", "m/s", "ENU", "up velocity"),
    "vf": ("velocity", "m/s", "level FLU", "forward velocity, parallel to the earth surface"),
    "vl": ("velocity", "m/s", "level FLU", "leftward velocity, parallel to the earth surface"),
    "ax": ("acceleration", "m/s^2", "body FLU", "acceleration along x, the vehicle front"),
    "ay": ("acceleration", "m/s^2", "body FLU", "acceleration along y, the vehicle left"),
    "az": ("acceleration", "m/s^2", "body FLU", "acceleration along z, the vehicle top"),
    "af": ("acceleration", "m/s^2", "level FLU", "forward acceleration"),
    "al": ("acceleration", "m/s^2", "level FLU", "leftward acceleration"),
    "au": ("acceleration", "m/s^2", "level FLU", "upward acceleration"),
    "wx": ("rate", "rad/s", "body FLU", "angular rate around x, the vehicle front"),
    "wy": ("rate", "rad/s", "body FLU", "angular rate around y, the vehicle left"),
    "wz": ("rate", "rad/s", "body FLU", "angular rate around z, the vehicle top"),
    "wf": ("rate", "rad/s", "level FLU", "angular rate around the forward axis"),
    "wl": ("rate", "rad/s", "level FLU", "angular rate around the leftward axis"),
    "wu": ("rate", "rad/s", "level FLU", "angular rate around the upward axis"),
    "pos_accuracy": ("accuracy", "m", "", "position accuracy"),
    "vel_accuracy": ("accuracy", "m/s", "", "velocity accuracy"),
    "navstat": ("status", "", "", "navigation status"),
    "numsats": ("status", "", "", "number of satellites tracked by the GPS receiver"),
    "posmode": ("status", "", "", "GPS position mode"),
    "velmode": ("status", "", "", "GPS velocity mode"),
    "orimode": ("status", "", "", "GPS orientation mode"),
    "depth": ("depth", "m", "down", "depth, positive down"),
    "height": ("height", "m", "up", "height above the bottom (DVL)"),
}

# Magnitude limits per kind for an AUV (|value| must stay below).
LIMITS = {
    "velocity": (10.0, "m/s"), "acceleration": (50.0, "m/s^2"), "rate": (10.0, "rad/s"),
    "roll": (np.pi + 1e-3, "rad"), "pitch": (np.pi / 2 + 1e-3, "rad"), "yaw": (np.pi + 1e-3, "rad"),
    "altitude": (10000.0, "m"), "depth": (12000.0, "m"), "height": (1000.0, "m"),
}
ACCURACY_LIMITS = {"m": 1000.0, "m/s": 10.0}

# Columns the README establishes as consistent come first when looking for
# duplicates: a later column that repeats an earlier one is the duplicate.
PRIORITY = ("time", "lat", "lon", "lat_gps", "lon_gps", "alt_gps", "alt",
            "roll", "pitch", "yaw", "wx", "wy", "wz")

GROUPS = {  # channel -> (columns, components, angle components, convention)
    "attitude": (("roll", "pitch", "yaw"), ("roll", "pitch", "yaw"), (0, 1, 2),
                 "roll: positive = left side up; pitch: positive = front down; "
                 "yaw: heading, 0 = east, counter-clockwise positive (ENU)"),
    "gyro": (("wx", "wy", "wz"), ("wx", "wy", "wz"), (),
             "body angular rates around x = front, y = left, z = top (right-handed)"),
}


def load(path, *, jump_threshold: float = 5.0, max_speed: float = 10.0,
         gps_tolerance: float = 15.0, gap_factor: float = 5.0) -> Frame:
    """Read one Bohai CSV log into a :class:`Frame`.

    ``jump_threshold`` (m per 0.1 s) defines a jump of the navigation solution,
    ``max_speed`` (m/s) the fastest plausible motion of the vehicle,
    ``gps_tolerance`` (m) how far a fresh GPS fix may lie from the navigation
    solution before it contradicts it (None: no GPS check), and
    ``gap_factor`` which time steps are flagged as gaps (> factor x median).
    """
    path = Path(path)
    data = _read_bytes(path)
    table, lines = _parse(path, data)
    layout = _layout(path, list(table.columns))
    report = Report()
    meta = {"source": str(path), "sha256": hashlib.sha256(data).hexdigest(),
            "layout": layout, "adapter": "bohai-csv", "dropped_columns": {}}
    names = COLS36 if layout == 36 else COLS31
    for c in table.columns:
        if c not in names:
            _drop(report, meta, c, len(table), f"not a column of the {layout}-column layout")
    cols, lines = _clean_rows(path, table, names, lines, report, meta)
    time = cols["time"]
    t = time - time[0]
    meta["time"] = _time_axis(t, lines, report, gap_factor)
    meta["time"]["offset"] = float(time[0])

    # projection, GPS fixes, reference position
    lat, lon = cols["lat"], cols["lon"]
    geo_ok = _plausible_latlon(lat, lon)
    if not geo_ok.any():
        raise DataError(path, "no plausible lat/lon in the navigation solution")
    if (~geo_ok).any():
        report.add("masked", "position", int((~geo_ok).sum()),
                   f"lat/lon missing or impossible at {_rows(lines, ~geo_ok)}")
    epsg = utm_epsg(lat[geo_ok], lon[geo_ok])
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", epsg, always_xy=True)
    utm = _project(to_utm, lat, lon, geo_ok)
    gps = _gps_fixes(cols, t, to_utm, lines, report, meta, jump_threshold, max_speed) \
        if layout == 36 else None
    valid = _reference_mask(t, utm, geo_ok, gps, lines, report, meta,
                            jump_threshold, max_speed, gps_tolerance)
    origin = utm[int(np.argmax(valid if valid.any() else geo_ok))].copy()
    meta.update(crs=f"EPSG:{epsg}", epsg=epsg, origin=[float(origin[0]), float(origin[1])])
    pos = utm - origin
    reference = {"position": Channel(pos, "m", "ENU local", valid, ("east", "north"),
                                     description="navigation solution lat/lon in UTM minus origin; "
                                                 "masked where displaced (see meta['jumps'])")}
    vel = track_velocity(t, pos, valid)
    meta["speed"] = _speed_check(vel, report)

    channels = _sensor_channels(cols, t, vel, lines, report, meta)
    if gps is not None:
        channels["gps_position"] = Channel(gps["utm"] - origin, "m", "ENU local", gps["valid"],
                                           ("east", "north"),
                                           description="GPS fix lat_gps/lon_gps in UTM minus origin; "
                                                       "valid only where a new fix appears")
    if layout == 36:
        _time_of_day(cols["time_gps"], t, report, meta)
    return Frame(t, channels, reference, None, meta, report)


def _drop(report, meta, column, count, reason):
    meta["dropped_columns"][column] = reason
    report.add("dropped", column, count, reason)


def _sensor_channels(cols, t, vel, lines, report, meta) -> dict:
    """Channels from the columns that pass the plausibility checks."""
    n = len(t)
    channels = {}
    for c, found in check_columns(cols, vel).items():
        if found:
            _drop(report, meta, c, n, "; ".join(found))
    passed = [c for c in cols if c in COLUMNS and c not in meta["dropped_columns"]]
    for name, (members, comps, angles, convention) in GROUPS.items():
        if all(c in passed for c in members):
            values = np.column_stack([cols[c] for c in members])
            frame = "body" if name == "attitude" else COLUMNS[members[0]][2]
            channels[name] = Channel(values, COLUMNS[members[0]][1], frame, None, comps, angles,
                                     convention, ", ".join(COLUMNS[c][3] for c in members))
            passed = [c for c in passed if c not in members]
    if "attitude" in channels:
        meta["yaw_course"] = _yaw_check(channels["attitude"].values[:, 2], vel, report)
    if "attitude" in channels and "gyro" in channels:
        meta["gyro_attitude"] = _gyro_check(t, channels["gyro"].values, channels["attitude"].values,
                                            report)
    for c in passed:
        kind, unit, frame, desc = COLUMNS[c]
        if kind == "altitude":
            name = "gps_alt" if c == "alt_gps" else c
            channels[name] = _fresh_alt(cols[c], t, lines, name, report)
            continue
        angles = (0,) if kind in ("roll", "pitch", "yaw") else ()
        channels[c] = Channel(cols[c], unit, frame, None, (c,), angles, "", desc)
    for name, ch in channels.items():
        bad = ~np.isfinite(ch.values.reshape(n, -1)).all(axis=1)
        if bad.any() and name not in ("gps_alt", "alt"):
            report.add("masked", name, int(bad.sum()), f"missing values at {_rows(lines, bad)}")
    return channels


# ---------------------------------------------------------------- reading

def _read_bytes(path: Path) -> bytes:
    if not path.exists():
        raise DataError(path, "file not found")
    if not path.is_file():
        raise DataError(path, "not a file")
    try:
        data = path.read_bytes()
    except OSError as err:
        raise DataError(path, f"cannot read: {err.strerror or err}") from None
    if not data.strip():
        raise DataError(path, "file is empty")
    return data


def _parse(path, data: bytes):
    """The table as floats and, per row, its 1-based line number in the file."""
    try:
        table = pd.read_csv(io.BytesIO(data), skip_blank_lines=False, encoding="utf-8-sig")
    except pd.errors.ParserError as err:
        last = str(err).strip().splitlines()[-1]
        line = re.search(r"line (\d+)", last)
        raise DataError(path, f"not a readable CSV table: {last}",
                        row=int(line.group(1)) if line else None) from None
    except (UnicodeDecodeError, ValueError) as err:
        raise DataError(path, f"not a readable CSV table: {err}") from None
    table.columns = [str(c).strip() for c in table.columns]
    if len(table) == 0:
        raise DataError(path, "header only, no data rows")
    lines = np.arange(len(table)) + 2  # header is line 1; blank lines stay rows
    bad_at = None
    for c in table.columns:
        col = table[c]
        if col.dtype.kind in "fiub":
            continue
        num = pd.to_numeric(col.astype(str).str.strip().replace({"nan": ""}).replace("", np.nan),
                            errors="coerce")
        bad = num.isna().to_numpy() & col.notna().to_numpy()
        if bad.any():
            i = int(np.argmax(bad))
            if bad_at is None or i < bad_at[0]:
                bad_at = (i, c, col.iloc[i])
        table[c] = num
    if bad_at is not None:
        i, c, v = bad_at
        raise DataError(path, f"non-numeric value {str(v)!r} in column {c}", row=int(lines[i]))
    return table.astype(float), lines


def _layout(path, columns) -> int:
    have = set(columns)
    missing = {36: [c for c in COLS36 if c not in have], 31: [c for c in COLS31 if c not in have]}
    for layout in (36, 31):
        if not missing[layout]:
            return layout
    near = min(missing, key=lambda k: len(missing[k]))
    raise DataError(path, f"header matches neither Bohai layout: missing columns "
                          f"{', '.join(missing[near])} (of the {near}-column layout)")


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
    empty = table.isna().to_numpy().all(axis=1)
    table = table[list(names)]
    values = table.to_numpy(dtype=float)
    if empty.any():
        report.add("dropped", "rows", int(empty.sum()),
                   f"empty or all-NaN rows at {_rows(lines, empty)}")
    no_time = ~empty & ~np.isfinite(table["time"].to_numpy())
    if no_time.any():
        report.add("dropped", "rows", int(no_time.sum()), f"no time value at {_rows(lines, no_time)}")
    keep = ~empty & ~no_time
    values, lines = values[keep], lines[keep]
    if len(lines) == 0:
        raise DataError(path, "no data rows with a time value")
    time = values[:, list(table.columns).index("time")]
    same = np.r_[False, np.diff(time) == 0]
    if same.any():
        prev = np.r_[values[:1], values[:-1]]
        identical = same & ((values == prev) | (np.isnan(values) & np.isnan(prev))).all(axis=1)
        if (same & ~identical).any():
            i = int(np.argmax(same & ~identical))
            raise DataError(path, f"time {time[i]:g} s repeats line {lines[i - 1]} with different "
                                  f"values (duplicate timestamp)", row=int(lines[i]))
        report.add("dropped", "rows", int(identical.sum()),
                   f"exact duplicates of the previous row at {_rows(lines, identical)}")
        values, lines, time = values[~identical], lines[~identical], time[~identical]
    back = np.diff(time) < 0
    if back.any():
        i = int(np.argmax(back)) + 1
        raise DataError(path, f"time decreases from {time[i - 1]:g} s (line {lines[i - 1]}) "
                              f"to {time[i]:g} s", row=int(lines[i]))
    if len(lines) < 2:
        raise DataError(path, "fewer than 2 usable data rows")
    meta["rows"] = {"read": n_read, "kept": len(lines), "dropped": n_read - len(lines)}
    return {c: values[:, j] for j, c in enumerate(table.columns)}, lines


def _time_axis(t, lines, report, gap_factor) -> dict:
    dt = np.diff(t)
    med = float(np.median(dt))
    gaps = dt > gap_factor * med
    stats = {"median_step": med, "min_step": float(dt.min()), "max_step": float(dt.max()),
             "span": float(t[-1]), "gaps": int(gaps.sum())}
    report.add("info", "time", len(t), f"median step {med:.4f} s, min {dt.min():.4f} s, "
                                       f"max {dt.max():.4f} s, span {t[-1]:.1f} s")
    if gaps.any():
        i = int(np.argmax(dt))
        report.add("flagged", "time", int(gaps.sum()),
                   f"gaps > {gap_factor:g} x median step "
                   f"(longest {dt[i]:.3f} s before line {lines[i + 1]})")
    return stats


# ---------------------------------------------------------------- geodesy

def utm_epsg(lat, lon) -> int:
    """EPSG code of the WGS 84 UTM zone of the data (median longitude, latitude sign)."""
    zone = int(np.floor((np.median(lon) + 180.0) / 6.0)) % 60 + 1
    return (32600 if np.median(lat) >= 0 else 32700) + zone


def _plausible_latlon(lat, lon):
    ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
    return ok & ~((lat == 0) & (lon == 0))


def _project(to_utm, lat, lon, ok):
    out = np.full((len(lat), 2), np.nan)
    e, nn = to_utm.transform(lon[ok], lat[ok])
    out[ok, 0], out[ok, 1] = e, nn
    return out


# ---------------------------------------------------------------- reference

def _reach(dt, jump_threshold, max_speed):
    """Largest plausible displacement (m) over ``dt`` seconds."""
    return np.minimum(jump_threshold * dt / NOMINAL_STEP, max_speed * dt + jump_threshold)


def find_jumps(t, p, jump_threshold=5.0, max_speed=10.0):
    """Indices of the samples that follow a jump: a step > jump_threshold per 0.1 s."""
    step = np.hypot(*np.diff(p, axis=0).T)
    return np.flatnonzero(step > _reach(np.diff(t), jump_threshold, max_speed)) + 1


def mask_jumps(t, p, jump_threshold=5.0, max_speed=10.0, block=10):
    """Keep-mask for a track ``p`` (n, 2) in metres (all finite).

    A *jump* is a step between consecutive samples longer than
    ``jump_threshold`` per 0.1 s (scaled by the actual step). Two samples are
    *compatible* when their distance is at most ``min(jump_threshold * dt /
    0.1, max_speed * dt + jump_threshold)``: never a jump, and across a masked
    gap no faster than ``max_speed`` plus one jump_threshold of slack. The
    kept samples are the largest set in which each kept sample is compatible
    with the next kept one, found by dynamic programming over blocks (the
    jump-free runs cut into pieces of ``block`` samples), then grown back
    sample by sample at the edges of each masked stretch. A spike or a
    displaced stretch that comes back (out and back) is masked as a whole; at
    a step that persists, the samples next to the step are masked until the
    rest is reachable at ``max_speed``. Nothing else is masked.
    """
    t = np.asarray(t, float)
    p = np.asarray(p, float)
    n = len(t)
    jumps = find_jumps(t, p, jump_threshold, max_speed) if n > 1 else np.zeros(0, int)
    if not len(jumps):
        return np.ones(n, bool)
    starts = np.union1d(np.arange(0, n, block), jumps)
    ends = np.r_[starts[1:], n] - 1
    best = np.zeros(len(starts))
    prev = np.full(len(starts), -1)
    for k in range(len(starts)):
        if k:
            d = np.hypot(*(p[ends[:k]] - p[starts[k]]).T)
            ok = d <= _reach(t[starts[k]] - t[ends[:k]], jump_threshold, max_speed)
            if ok.any():
                cand = np.where(ok, best[:k], -1.0)
                prev[k] = k - 1 - int(np.argmax(cand[::-1]))  # the latest among equals
                best[k] = best[prev[k]]
        best[k] += ends[k] - starts[k] + 1
    keep = np.zeros(n, bool)
    k = len(starts) - 1 - int(np.argmax(best[::-1]))
    while k >= 0:
        keep[starts[k]:ends[k] + 1] = True
        k = prev[k]
    _regrow(t, p, keep, jump_threshold, max_speed)
    return keep


def _regrow(t, p, keep, jump_threshold, max_speed):
    """Unmask samples at the edges of masked stretches while they stay compatible."""
    def ok(i, j):
        if i is None or j is None:
            return True
        return np.hypot(*(p[j] - p[i])) <= _reach(t[j] - t[i], jump_threshold, max_speed)

    n = len(t)
    for a, b in _runs(~keep):
        lo = a - 1 if a > 0 else None
        hi = b + 1 if b < n - 1 else None
        while b >= a and ok(b, hi) and ok(lo, b):
            keep[b] = True
            hi, b = b, b - 1
        while a <= b and ok(lo, a) and ok(a, hi):
            keep[a] = True
            lo, a = a, a + 1


def _runs(mask):
    """(first, last) index pairs of the runs of True in ``mask``."""
    idx = np.flatnonzero(mask)
    if not len(idx):
        return []
    cut = np.flatnonzero(np.diff(idx) > 1)
    return list(zip(np.r_[idx[0], idx[cut + 1]], np.r_[idx[cut], idx[-1]]))


def gps_contradiction(t, p, fixes, fix_p, after_jump, tolerance=15.0, window=1.0):
    """Reference samples that fresh GPS fixes contradict, and each fix's distance.

    ``fixes`` are the sample indices of fresh, valid fixes at ``fix_p``; ``p``
    is the reference (NaN where unknown); ``after_jump`` marks the samples
    that follow a jump of the reference. A fix contradicts the reference when
    they are more than ``tolerance`` apart at the fix. Masked: the samples
    whose nearest fix (within ``window`` s) contradicts the reference, and all
    samples between two consecutive contradicting fixes when the reference
    makes no jump between them (its offset cannot have gone away).
    """
    n = len(t)
    out = np.zeros(n, bool)
    if not len(fixes):
        return out, np.zeros(0)
    dist = np.hypot(*(p[fixes] - fix_p).T)
    bad = dist > tolerance
    tf = t[fixes]
    k = np.clip(np.searchsorted(tf, t), 1, max(len(tf) - 1, 1))
    left = np.minimum(k - 1, len(tf) - 1)
    right = np.minimum(k, len(tf) - 1)
    near = np.where(np.abs(t - tf[left]) <= np.abs(tf[right] - t), left, right)
    out |= (np.abs(t - tf[near]) <= window) & bad[near]
    seg = np.cumsum(after_jump)
    pair = bad[:-1] & bad[1:] & (seg[fixes[:-1]] == seg[fixes[1:]])
    mark = np.zeros(n + 1, int)
    np.add.at(mark, fixes[:-1][pair], 1)
    np.add.at(mark, fixes[1:][pair] + 1, -1)
    out |= np.cumsum(mark)[:n] > 0
    return out, dist


def _reference_mask(t, utm, geo_ok, gps, lines, report, meta, jump_threshold, max_speed,
                    gps_tolerance):
    """Validity of the reference: plausible lat/lon, not contradicted by GPS, no jumps.

    Two stages. First (36-column files) the samples that fresh GPS fixes
    contradict (:func:`gps_contradiction`): this decides which side of a
    persistent step is displaced whenever the vehicle is at the surface.
    Then :func:`mask_jumps` on what is left removes spikes, displaced
    stretches and the samples next to the remaining steps.
    """
    n = len(t)
    idx = np.flatnonzero(geo_ok)
    jumps = idx[find_jumps(t[idx], utm[idx], jump_threshold, max_speed)]
    steps = np.hypot(*(utm[jumps] - utm[idx[np.searchsorted(idx, jumps) - 1]]).T)
    valid = geo_ok.copy()
    contra = np.zeros(n, bool)
    gps_check = gps is not None and gps_tolerance is not None
    if gps_check:
        fixes = np.flatnonzero(gps["valid"])
        after_jump = np.zeros(n, bool)
        after_jump[jumps] = True
        contra, dist = gps_contradiction(t, utm, fixes, gps["utm"][fixes], after_jump, gps_tolerance)
        contra &= geo_ok
        valid &= ~contra
        far = dist > gps_tolerance
        gps["info"].update(median_distance_to_reference_m=float(np.nanmedian(dist)),
                           fixes_contradicting_reference=int(far.sum()))
        worst = int(np.nanargmax(np.nan_to_num(dist, nan=-1.0)))
        report.add("info", "gps_position", len(fixes),
                   f"fresh fixes vs navigation solution: median {np.nanmedian(dist):.1f} m, "
                   f"{int(far.sum())} fixes > {gps_tolerance:g} m (largest {dist[worst]:.1f} m "
                   f"at line {lines[fixes[worst]]})")
        if contra.any():
            report.add("masked", "position", int(contra.sum()),
                       f"contradicted by fresh GPS fixes: {int(far.sum())} fixes > {gps_tolerance:g} m "
                       f"from the navigation solution; samples within 1 s of them, and between "
                       f"consecutive ones without a jump, masked ({len(_runs(contra))} stretches)")
    rest = np.flatnonzero(valid)
    keep = mask_jumps(t[rest], utm[rest], jump_threshold, max_speed)
    kinematic = np.zeros(n, bool)
    kinematic[rest[~keep]] = True
    valid &= ~kinematic
    masked = contra | kinematic
    meta["jumps"] = {
        "events": len(jumps), "largest_m": float(steps.max()) if len(steps) else 0.0,
        "masked": int(masked.sum()), "masked_gps": int(contra.sum()),
        "masked_kinematic": int(kinematic.sum()), "stretches": len(_runs(masked)),
        "steps": [{"line": int(lines[i]), "t": float(t[i]), "step_m": float(s)}
                  for i, s in zip(jumps, steps)],
        "method": (f"masked where fresh GPS fixes contradict it by > {gps_tolerance:g} m, then "
                   if gps_check else "") +
                  f"the largest set of samples with no step > {jump_threshold:g} m per 0.1 s and "
                  f"no motion > {max_speed:g} m/s across masked stretches"}
    if len(jumps):
        i = int(np.argmax(steps))
        report.add("masked", "position", int(kinematic.sum()),
                   f"{len(jumps)} jumps > {jump_threshold:g} m per 0.1 s in the navigation solution "
                   f"(largest {steps[i]:.1f} m at line {lines[jumps[i]]}); {int(kinematic.sum())} "
                   f"displaced samples in {len(_runs(kinematic))} stretches masked so that no "
                   f"kept step is a jump and no masked gap is crossed faster than {max_speed:g} m/s")
    return valid


# ---------------------------------------------------------------- track checks

def track_velocity(t, p, valid, window=2.0):
    """(n, 2) velocity from positions over ``window`` s centred on each sample.

    NaN where the window holds a masked sample or is shorter than half the window.
    """
    n = len(t)
    lo = np.searchsorted(t, t - window / 2)
    hi = np.searchsorted(t, t + window / 2, side="right") - 1
    bad = np.r_[0, np.cumsum(~valid)]
    span = t[hi] - t[lo]
    ok = (bad[hi + 1] - bad[lo] == 0) & (span >= window / 2)
    v = np.full((n, 2), np.nan)
    v[ok] = (p[hi[ok]] - p[lo[ok]]) / span[ok, None]
    return v


def _speed_check(vel, report) -> dict:
    speed = np.hypot(vel[:, 0], vel[:, 1])
    speed = speed[np.isfinite(speed)]
    if not len(speed):
        return {}
    out = {"median": float(np.median(speed)), "p95": float(np.percentile(speed, 95)),
           "max": float(speed.max())}
    report.add("info", "position", len(speed),
               f"position-derived speed median {out['median']:.2f} m/s, 95th percentile "
               f"{out['p95']:.2f} m/s, max {out['max']:.2f} m/s")
    return out


def _yaw_check(yaw, vel, report, min_speed=0.5) -> dict:
    """Agreement of yaw with the course over ground (at speed > ``min_speed``)."""
    speed = np.hypot(vel[:, 0], vel[:, 1])
    sel = np.isfinite(speed) & (speed > min_speed) & np.isfinite(yaw)
    if sel.sum() < 10:
        report.add("info", "attitude", int(sel.sum()),
                   "too few samples at speed to compare yaw with course")
        return {"samples": int(sel.sum())}
    course = np.arctan2(vel[sel, 1], vel[sel, 0])
    signed = wrap(yaw[sel] - course)
    diff = np.abs(signed)
    med = float(np.median(diff))
    out = {"samples": int(sel.sum()), "median_abs_rad": med, "median_rad": float(np.median(signed)),
           "p90_abs_rad": float(np.percentile(diff, 90))}
    report.add("info", "attitude", int(sel.sum()),
               f"yaw vs course over ground at > {min_speed:g} m/s: median |difference| {med:.3f} rad "
               f"(median signed {out['median_rad']:+.3f} rad)")
    if med > 0.5:
        report.add("flagged", "attitude", int(sel.sum()),
                   f"yaw disagrees with the course over ground (median {med:.2f} rad)")
    return out


def _gyro_check(t, w, att, report, window=1.0) -> dict:
    """Correlation of each gyro axis with the rate of the matching attitude angle.

    Over ``window`` s, wx ~ roll rate, wy ~ pitch rate, wz ~ yaw rate (small
    roll and pitch). Reported, and flagged below 0.3; not a reason to drop.
    """
    k = max(1, int(round(window / np.median(np.diff(t)))))
    if len(t) <= 2 * k:
        return {}
    rate = wrap(att[k:] - att[:-k]) / (t[k:] - t[:-k])[:, None]
    mean = np.cumsum(np.r_[np.zeros((1, 3)), w], axis=0)
    mean = (mean[k + 1:] - mean[1:-k]) / k  # w averaged over samples i+1 .. i+k
    ok = np.isfinite(rate).all(axis=1) & np.isfinite(mean).all(axis=1)
    if ok.sum() < 10:
        return {}
    corr = [float(np.corrcoef(mean[ok, i], rate[ok, i])[0, 1]) for i in range(3)]
    out = {"wx_roll": corr[0], "wy_pitch": corr[1], "wz_yaw": corr[2]}
    report.add("info", "gyro", int(ok.sum()),
               "correlation with attitude rates: " + ", ".join(f"{k} {v:.2f}" for k, v in out.items()))
    weak = [k for k, v in out.items() if not v >= 0.3]
    if weak:
        report.add("flagged", "gyro", int(ok.sum()),
                   f"weak correlation with attitude rates ({', '.join(weak)} < 0.3): a gyro axis or "
                   f"an attitude angle may not hold what its header says")
    return out


# ---------------------------------------------------------------- column checks

def check_constant(x):
    """'all zero' / 'constant c' when a column never changes."""
    f = x[np.isfinite(x)]
    if not len(f):
        return "no values"
    if np.all(f == f[0]):
        return "all zero" if f[0] == 0 else f"constant {f[0]:g}"
    return None


def check_limit(x, limit, unit):
    m = np.nanmax(np.abs(x))
    return f"|value| up to {m:.1f} > {limit:g} {unit} limit" if m > limit else None


def check_nonnegative(x):
    m = np.nanmin(x)
    return f"negative values (down to {m:.3g}) for an accuracy or range" if m < 0 else None


def check_integer(x):
    f = x[np.isfinite(x)]
    frac = f != np.round(f)
    return f"non-integer values (e.g. {f[frac][0]:.6g}) for a status or count" if frac.any() else None


def find_duplicate(x, earlier: dict):
    """'duplicate of column c' when ``x`` repeats (or negates) an earlier column."""
    head = x[:16]
    for name, y in earlier.items():
        if not (np.array_equal(head, y[:16], equal_nan=True)
                or np.array_equal(head, -y[:16], equal_nan=True)):
            continue  # cheap test first
        if np.array_equal(x, y, equal_nan=True):
            return f"duplicate of column {name}"
        if np.array_equal(x, -y, equal_nan=True):
            return f"negated duplicate of column {name}"
    return None


def check_agreement(x, ref, tol, unit, what):
    """Median |x - ref| above ``tol`` where both are known."""
    sel = np.isfinite(x) & np.isfinite(ref)
    if sel.sum() < 10:
        return None
    d = float(np.median(np.abs(x[sel] - ref[sel])))
    scale = float(np.median(np.abs(ref[sel])))
    if d > max(tol, 0.5 * scale):
        return (f"disagrees with {what} (median |difference| {d:.2f} {unit}, "
                f"median |{what}| {scale:.2f} {unit})")
    return None


def check_columns(cols, vel) -> dict:
    """Findings (list of strings, empty when plausible) for every sensor column.

    Per column: constant (status columns may be), duplicate or negated
    duplicate of a column earlier in :data:`PRIORITY` then file order,
    magnitude limit of its kind, sign (accuracies, height), integer values
    (status and counts), and for vn/ve agreement with the velocity derived
    from the reference track ``vel`` (n, 2).
    """
    order = [c for c in PRIORITY if c in cols] + [c for c in cols if c not in PRIORITY]
    findings = {}
    seen = {}
    for c in order:
        x = cols[c]
        if c not in COLUMNS:
            if c in ("lat", "lon", "lat_gps", "lon_gps", "time"):
                seen[c] = x
            continue
        kind, unit = COLUMNS[c][:2]
        const = check_constant(x)
        found = []
        if const and kind == "status":  # a constant mode or count is plausible
            found.append(check_integer(x))
        elif const:
            found.append(const)
        else:
            found.append(find_duplicate(x, seen))
            seen[c] = x
            if kind in LIMITS:
                found.append(check_limit(x, *LIMITS[kind]))
            if kind == "accuracy":
                found += [check_nonnegative(x), check_limit(x, ACCURACY_LIMITS[unit], unit)]
            if kind == "height":
                found.append(check_nonnegative(x))
            if kind == "status":
                found.append(check_integer(x))
            if c in ("ve", "vn") and not any(found):
                ref = vel[:, 0] if c == "ve" else vel[:, 1]
                what = f"position-derived {'east' if c == 've' else 'north'} velocity"
                found.append(check_agreement(x, ref, 0.3, "m/s", what))
        findings[c] = [f for f in found if f]
    return findings


# ---------------------------------------------------------------- GPS

def fresh_mask(*columns):
    """True where any of the columns changed from the previous row (a new fix)."""
    changed = np.zeros(len(columns[0]), bool)
    for x in columns:
        changed[1:] |= ~((x[1:] == x[:-1]) | (np.isnan(x[1:]) & np.isnan(x[:-1])))
    return changed


def stale_stretches(t, fresh):
    """Durations (s) for which the columns held the same value: start, between fixes, end."""
    idx = np.flatnonzero(fresh)
    if not len(idx):
        return np.array([t[-1] - t[0]])
    return np.diff(np.r_[t[0], t[idx], t[-1]])


def _gps_fixes(cols, t, to_utm, lines, report, meta, jump_threshold, max_speed):
    """GPS fixes in UTM, valid where a new plausible fix appears, or None.

    The GPS columns hold the last fix while the vehicle is submerged: only a
    row where lat_gps or lon_gps changes is a measurement (the first row's fix
    is of unknown age and is not counted). Rows at 0/0 or outside the globe
    are invalid and skipped when looking for changes. Fixes that jump away
    from their neighbours (:func:`mask_jumps` on the sequence of fresh fixes)
    are invalid too.
    """
    lat, lon = cols["lat_gps"], cols["lon_gps"]
    n = len(t)
    for c in ("lat_gps", "lon_gps"):
        const = check_constant(cols[c])
        if const in ("all zero", "no values"):
            _drop(report, meta, c, n, const)
    if "lat_gps" in meta["dropped_columns"] or "lon_gps" in meta["dropped_columns"]:
        return None
    plausible = _plausible_latlon(lat, lon)
    bad = ~plausible & np.isfinite(lat) & np.isfinite(lon)
    fresh = np.zeros(n, bool)  # changed from the last plausible fix
    fresh[plausible] = fresh_mask(lat[plausible], lon[plausible])
    utm = _project(to_utm, lat, lon, plausible)
    valid = fresh.copy()
    idx = np.flatnonzero(valid)
    keep = mask_jumps(t[idx], utm[idx], jump_threshold, max_speed)
    outliers = np.zeros(n, bool)
    outliers[idx[~keep]] = True
    valid &= ~outliers
    stretches = stale_stretches(t, fresh)
    info = {"fresh": int(fresh.sum()), "valid": int(valid.sum()),
            "stale": int((plausible & ~fresh).sum()),
            "longest_stale_s": float(stretches.max()), "stale_over_10s": int((stretches > 10).sum()),
            "implausible": int(bad.sum()), "outliers": int(outliers.sum())}
    meta["gps"] = info
    report.add("info", "gps_position", info["fresh"],
               f"{info['fresh']} fresh fixes (lat_gps/lon_gps changed), {info['stale']} stale samples "
               f"repeating the last fix; longest stale stretch {info['longest_stale_s']:.1f} s")
    if bad.any():
        report.add("masked", "gps_position", int(bad.sum()),
                   f"rows with zero or impossible lat_gps/lon_gps at {_rows(lines, bad)}")
    if outliers.any():
        report.add("masked", "gps_position", int(outliers.sum()),
                   f"fixes jumping > {jump_threshold:g} m per 0.1 s, or faster than {max_speed:g} m/s, "
                   f"from their neighbours at {_rows(lines, outliers)}")
    if not valid.any():
        for c in ("lat_gps", "lon_gps"):
            _drop(report, meta, c, n, "no fresh plausible GPS fix")
        return None
    return {"utm": utm, "valid": valid, "info": info}


def _fresh_alt(x, t, lines, name, report) -> Channel:
    fresh = fresh_mask(x)
    zero = fresh & (x == 0)
    valid = fresh & ~zero & np.isfinite(x)
    longest = float(stale_stretches(t, fresh).max())
    report.add("info", name, int(fresh.sum()),
               f"{int(fresh.sum())} new values, {int(len(x) - fresh.sum())} repeats; "
               f"longest repeat {longest:.1f} s")
    if zero.any():
        report.add("masked", name, int(zero.sum()), f"zero altitude at {_rows(lines, zero)}")
    return Channel(x, "m", "up", valid, (name,),
                   description="altitude; valid only where a new value appears")


def _time_of_day(x, t, report, meta):
    """Record ``time_gps`` read as hhmmss when it is a plausible GPS time of day.

    In 20220625_0_0 it is: the value changes with each GPS fix and hhmmss
    minus ``t`` stays within 0.3 s, giving t = 0 at 05:20:13.6.
    """
    f = np.isfinite(x)
    const = check_constant(x)
    h, m, s = x // 10000, (x // 100) % 100, x % 100
    ok = f & (x >= 0) & (h < 24) & (m < 60) & (s < 60) & (x == np.round(x))
    changed = fresh_mask(x) & ok
    reason = None
    if const:
        reason = const
    elif not ok[f].all():
        reason = "values that are not hhmmss times of day"
    elif changed.sum() < 3:
        reason = "too few updates to relate to time"
    else:
        sod = h * 3600 + m * 60 + s
        offset = sod[changed] - t[changed]
        if np.ptp(offset) > 3.0:
            reason = f"does not advance with time (offset spread {np.ptp(offset):.1f} s)"
    if reason:
        _drop(report, meta, "time_gps", len(x), reason)
        return
    t0 = float(np.median(offset)) % 86400
    hh, rem = divmod(t0, 3600)
    mm, ss = divmod(rem, 60)
    meta["gps_time_of_day"] = {"column": "time_gps", "format": "hhmmss", "t0_seconds_of_day": t0,
                               "t0_hhmmss": f"{int(hh):02d}:{int(mm):02d}:{ss:04.1f}",
                               "resolution_s": 1.0, "updates": int(changed.sum()),
                               "note": "time of day of t = 0 from the GPS fixes; the date is not "
                                       "in the file, so no epoch is set"}
    report.add("info", "time_gps", int(changed.sum()),
               f"read as GPS time of day hhmmss: t = 0 at {meta['gps_time_of_day']['t0_hhmmss']} "
               f"(+-1 s); no date, so no epoch")
