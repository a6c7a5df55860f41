"""GPS columns of the 36-column layout: fresh fixes, stale values, altitude, time of day."""

from __future__ import annotations

import numpy as np

from replay.adapters.geodesy import plausible_latlon, project
from replay.frame import Channel

from .columns import check_constant
from .reading import _drop, _rows
from .reference import mask_jumps


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
    plausible = plausible_latlon(lat, lon)
    bad = ~plausible & np.isfinite(lat) & np.isfinite(lon)
    fresh = np.zeros(n, bool)  # changed from the last plausible fix
    fresh[plausible] = fresh_mask(lat[plausible], lon[plausible])
    utm = project(to_utm, lat, lon, plausible)
    valid = fresh.copy()
    idx = np.flatnonzero(valid)
    keep = mask_jumps(t[idx], utm[idx], jump_threshold, max_speed)
    outliers = np.zeros(n, bool)
    outliers[idx[~keep]] = True
    valid &= ~outliers
    stretches = stale_stretches(t, fresh)
    info = {
        "fresh": int(fresh.sum()),
        "valid": int(valid.sum()),
        "stale": int((plausible & ~fresh).sum()),
        "longest_stale_s": float(stretches.max()),
        "stale_over_10s": int((stretches > 10).sum()),
        "implausible": int(bad.sum()),
        "outliers": int(outliers.sum()),
    }
    meta["gps"] = info
    report.add(
        "info",
        "gps_position",
        info["fresh"],
        f"{info['fresh']} fresh fixes (lat_gps/lon_gps changed), {info['stale']} stale samples "
        f"repeating the last fix; longest stale stretch {info['longest_stale_s']:.1f} s",
    )
    if bad.any():
        report.add(
            "masked",
            "gps_position",
            int(bad.sum()),
            f"rows with zero or impossible lat_gps/lon_gps at {_rows(lines, bad)}",
        )
    if outliers.any():
        report.add(
            "masked",
            "gps_position",
            int(outliers.sum()),
            f"fixes jumping > {jump_threshold:g} m per 0.1 s, or faster than {max_speed:g} m/s, "
            f"from their neighbours at {_rows(lines, outliers)}",
        )
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
    report.add(
        "info",
        name,
        int(fresh.sum()),
        f"{int(fresh.sum())} new values, {int(len(x) - fresh.sum())} repeats; longest repeat {longest:.1f} s",
    )
    if zero.any():
        report.add("masked", name, int(zero.sum()), f"zero altitude at {_rows(lines, zero)}")
    return Channel(x, "m", "up", valid, (name,), description="altitude; valid only where a new value appears")


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
    meta["gps_time_of_day"] = {
        "column": "time_gps",
        "format": "hhmmss",
        "t0_seconds_of_day": t0,
        "t0_hhmmss": f"{int(hh):02d}:{int(mm):02d}:{ss:04.1f}",
        "resolution_s": 1.0,
        "updates": int(changed.sum()),
        "note": "time of day of t = 0 from the GPS fixes; the date is not in the file, so no epoch is set",
    }
    report.add(
        "info",
        "time_gps",
        int(changed.sum()),
        f"read as GPS time of day hhmmss: t = 0 at {meta['gps_time_of_day']['t0_hhmmss']} "
        f"(+-1 s); no date, so no epoch",
    )
