"""The two Bohai header layouts, what each column holds, and the per-column plausibility checks."""

from __future__ import annotations

import numpy as np

# the columns both layouts share, between the position fix and the times
_SHARED = (
    "roll",
    "pitch",
    "yaw",
    "vn",
    "ve",
    "vf",
    "vl",
    "vu",
    "ax",
    "ay",
    "az",
    "af",
    "al",
    "au",
    "wx",
    "wy",
    "wz",
    "wf",
    "wl",
    "wu",
    "pos_accuracy",
    "vel_accuracy",
    "navstat",
    "numsats",
    "posmode",
    "velmode",
    "orimode",
)
COLS36 = ("lat_gps", "lon_gps", "alt_gps", *_SHARED, "lat", "lon", "depth", "height", "time", "time_gps")
COLS31 = ("lat", "lon", "alt", *_SHARED, "time")

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
    "velocity": (10.0, "m/s"),
    "acceleration": (50.0, "m/s^2"),
    "rate": (10.0, "rad/s"),
    "roll": (np.pi + 1e-3, "rad"),
    "pitch": (np.pi / 2 + 1e-3, "rad"),
    "yaw": (np.pi + 1e-3, "rad"),
    "altitude": (10000.0, "m"),
    "depth": (12000.0, "m"),
    "height": (1000.0, "m"),
}
ACCURACY_LIMITS = {"m": 1000.0, "m/s": 10.0}

# Columns the README establishes as consistent come first when looking for
# duplicates: a later column that repeats an earlier one is the duplicate.
PRIORITY = ("time", "lat", "lon", "lat_gps", "lon_gps", "alt_gps", "alt", "roll", "pitch", "yaw", "wx", "wy", "wz")

GROUPS = {  # channel -> (columns, components, angle components, convention)
    "attitude": (
        ("roll", "pitch", "yaw"),
        ("roll", "pitch", "yaw"),
        (0, 1, 2),
        "roll: positive = left side up; pitch: positive = front down; "
        "yaw: heading, 0 = east, counter-clockwise positive (ENU)",
    ),
    "gyro": (
        ("wx", "wy", "wz"),
        ("wx", "wy", "wz"),
        (),
        "body angular rates around x = front, y = left, z = top (right-handed)",
    ),
}


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
        if not (np.array_equal(head, y[:16], equal_nan=True) or np.array_equal(head, -y[:16], equal_nan=True)):
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
        return f"disagrees with {what} (median |difference| {d:.2f} {unit}, median |{what}| {scale:.2f} {unit})"
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
