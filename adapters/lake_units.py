"""Units of a lake-trial log: every declared unit checked against what the values can be.

A unit that contradicts the values is refused in one line naming the file, the column and the
likely unit (:class:`~replay.util.errors.DataError`); nothing is rescaled silently. Checks, in
the order :mod:`replay.adapters.lake` applies them:

* time: the median step must be a plausible sensor step (:data:`STEP_RANGE`) in the declared unit;
* every column: values outside the plausible range of their kind (:data:`RANGES`, in SI after
  the declared unit) are masked and counted when they are a few; when they are most of the
  column the unit is wrong (e.g. a speed in cm/s named ``speed_mps``): refused. Pitch in
  radians beyond pi/2 is refused (degrees), pitch in degrees that never leaves +-0.5 deg is
  flagged (perhaps radians);
* depth against the motion (:func:`depth_scale`): over 2 s windows, the change of depth
  against the integral of speed x sin(pitch) (eq. 4 of paper 000). A scale far from 1
  (beyond :data:`FAR`) means the depth unit (``depth_cm`` holding metres: 0.01) is wrong;
  the reference depth is checked the same way;
* a sensor against its reference (same kind): a scale far from 1 between the two means one of
  the two units is wrong; the one the motion check did not clear is named.

A check that cannot tell (too little motion, weak correlation) says nothing.
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import DataError

STEP_RANGE = (1e-3, 10.0)  # s: plausible median step of a sensor log (1 kHz .. 0.1 Hz)
UNITS = {  # kind -> {unit spelling: factor to SI}
    "time": {"s": 1.0, "sec": 1.0, "ms": 1e-3},
    "depth": {"m": 1.0, "cm": 1e-2, "mm": 1e-3},
    "speed": {
        "m/s": 1.0,
        "mps": 1.0,
        "m_s": 1.0,
        "ms-1": 1.0,
        "cm/s": 1e-2,
        "cmps": 1e-2,
        "kn": 0.514444,
        "knots": 0.514444,
        "kt": 0.514444,
    },
    "pitch": {"rad": 1.0, "deg": np.pi / 180, "degrees": np.pi / 180, "°": np.pi / 180},
}
SI = {"time": "s", "depth": "m", "speed": "m/s", "pitch": "rad"}
RANGES = {"depth": (-10.0, 11000.0), "speed": (-2.0, 20.0), "pitch": (-np.pi / 2, np.pi / 2)}
FAR = 3.0  # a scale beyond FAR or below 1/FAR between two measures of one quantity: a unit is wrong
MOST = 0.5  # more than this share of a column outside its kind's range: the unit is wrong
WINDOW = 2.0  # s: depth changes are compared over windows of this length
MIN_MOTION = 0.05  # m: spread of the depth changes the motion implies, below which depth_scale says nothing
MIN_CORR = 0.5  # correlation below which a scale is not trusted
TYPICAL_SPEED = (0.1, 5.0)  # m/s: median speed of an AUV under way; outside, the speed's unit is suspect too


def likely_unit(kind: str, declared: str, scale: float) -> str | None:
    """The unit of ``kind`` the values are in when, read in ``declared``, they come out ``scale``
    times the truth (None when no unit is within a factor 2 of it)."""
    want = UNITS[kind][declared] / scale
    best = min(UNITS[kind], key=lambda u: abs(np.log(UNITS[kind][u] / want)))
    return best if abs(np.log(UNITS[kind][best] / want)) < np.log(2) else None


def check_step(path, col, unit, steps) -> None:
    """Refuse a median time step that contradicts the declared unit."""
    med, (lo, hi), seconds = float(np.median(steps)), STEP_RANGE, UNITS["time"][unit] == 1.0
    if not lo <= med <= hi:
        guess = (
            "milliseconds (name it time_ms)"
            if med > hi and seconds
            else "seconds (name it time_s)"
            if med < lo and not seconds
            else "another unit"
        )
        raise DataError(
            path,
            f"column {col}: median time step {med:.4g} s is implausible for a sensor log "
            f"(expected {lo:g}-{hi:g} s): are the times in {guess}?",
        )


def check_range(path, col, kind, unit, v, report) -> np.ndarray:
    """``v`` (SI) with the few values outside the kind's range masked (counted); refused when most
    are, or when pitch contradicts its unit (module docstring)."""
    lo, hi = RANGES[kind]
    fin = np.isfinite(v)
    if kind == "pitch" and fin.any():
        peak = float(np.abs(v[fin]).max())
        if UNITS["pitch"][unit] == 1.0 and peak > np.pi / 2:
            raise DataError(
                path,
                f"column {col}: values reach {peak:.3g}, beyond pi/2 rad: "
                "the column looks like degrees (name it pitch_deg)",
            )
        if UNITS["pitch"][unit] != 1.0 and peak < np.deg2rad(0.5):
            report.add(
                "flagged",
                col,
                int(fin.sum()),
                f"declared degrees but never beyond {np.rad2deg(peak):.3g} deg: is it radians?",
            )
    out = fin & ((v < lo) | (v > hi))
    if out.sum() > MOST * fin.sum():
        raw = v[fin] / UNITS[kind][unit]
        fits = [
            u
            for u, f in UNITS[kind].items()
            if UNITS[kind][u] != UNITS[kind][unit] and np.mean((raw * f >= lo) & (raw * f <= hi)) > 0.99
        ]
        fits = list(dict.fromkeys(fits, None))[:3]
        guess = f"; the values fit {' or '.join(fits)}" if fits else ""
        raise DataError(
            path,
            f"column {col}: {int(out.sum())} of {int(fin.sum())} values are outside the "
            f"plausible {kind} range [{lo:g}, {hi:g}] {SI[kind]} when read in {unit}: "
            f"the unit is wrong{guess}",
        )
    if out.any():
        report.add("masked", col, int(out.sum()), f"outside the plausible {kind} range [{lo:g}, {hi:g}] {SI[kind]}")
        v = np.where(out, np.nan, v)
    return v


def _scale(a, b, min_spread):
    """Least-squares slope of ``a`` on ``b`` (with an intercept) where both are finite, or None
    when neither varies by ``min_spread`` or the two correlate weakly."""
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 10:
        return None
    a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
    sa, sb = float(np.sqrt(np.mean(a * a))), float(np.sqrt(np.mean(b * b)))
    if max(sa, sb) < min_spread or sa == 0.0 or sb == 0.0 or abs(float(np.mean(a * b))) < MIN_CORR * sa * sb:
        return None
    return float(np.mean(a * b) / (sb * sb))


def depth_scale(t, depth, speed, pitch):
    """Scale of the depth changes against speed x sin(pitch) integrated over :data:`WINDOW`
    (1 when the units agree; None when the motion cannot tell)."""
    k = max(1, int(round(WINDOW / float(np.median(np.diff(t))))))
    if len(t) <= k:
        return None
    w = speed * np.sin(pitch)
    fin = np.isfinite(w)
    wf = np.where(fin, w, 0.0)
    climb = np.r_[0.0, np.cumsum(0.5 * (wf[1:] + wf[:-1]) * np.diff(t))]
    missing = np.r_[0, np.cumsum(~fin)]  # missing[i]: missing values among w[:i]
    ok = missing[k + 1 :] - missing[: -k - 1] == 0  # window i .. i + k complete
    b = np.where(ok, climb[k:] - climb[:-k], np.nan)
    return _scale(depth[k:] - depth[:-k], b, MIN_MOTION)


def _far(s) -> bool:
    return s is not None and not 1 / FAR <= abs(s) <= FAR


def check_units(path, t, channels, reference, cols, units, report) -> None:
    """Depth (sensor and reference) against the motion, each sensor against its reference; refuse
    a contradicted unit, naming the column the other checks do not clear (module docstring).
    ``cols``/``units``: (is_ref, kind) -> column name / declared unit; values SI on the times ``t``."""
    pair = {
        k: _scale(_values(reference[k]), channels[k].values, 0.0)
        for k in ("depth", "speed", "pitch")
        if k in channels and k in reference
    }
    motion = {}
    if all(k in channels for k in ("depth", "speed", "pitch")):
        for ref, group in ((False, channels), (True, reference)):
            if "depth" in group:
                motion[ref] = depth_scale(
                    t, _values(group["depth"]), channels["speed"].values, channels["pitch"].values
                )
    name = lambda ref, kind: cols[(ref, kind)]  # noqa: E731
    if _far(pair.get("speed")):  # the sensor whose depth motion agrees is right
        m = motion.get(False)
        wrong = (
            True
            if m is not None and not _far(m)
            else False
            if _far(m) and abs(np.log(abs(m / pair["speed"]))) < np.log(FAR)
            else None
        )
        _refuse(path, "speed", pair["speed"], wrong, cols, units)
    if _far(pair.get("pitch")):
        _refuse(path, "pitch", pair["pitch"], None, cols, units)
    for ref, m in motion.items():
        if m is not None and m < 0:
            report.add(
                "flagged",
                name(ref, "depth"),
                len(t),
                f"depth falls where {name(False, 'speed')} and "
                f"{name(False, 'pitch')} say the vehicle dives (scale {m:.2g} against speed x "
                "sin(pitch)): depth or pitch sign convention?",
            )
        elif _far(m):
            col, unit = name(ref, "depth"), units[(ref, "depth")]
            guess = likely_unit("depth", unit, m)
            v = float(np.nanmedian(np.abs(channels["speed"].values)))
            speed = (
                ""
                if TYPICAL_SPEED[0] <= v <= TYPICAL_SPEED[1]
                else f", or {name(False, 'speed')} is not in {units[(False, 'speed')]} (median {v:.3g} m/s)"
            )
            raise DataError(
                path,
                f"column {col}: depth changes are {m:.3g} x what {name(False, 'speed')} and "
                f"{name(False, 'pitch')} imply (speed x sin(pitch)): {col} is not in {unit}"
                + (f" (it looks like {guess})" if guess else "")
                + speed,
            )
    if _far(pair.get("depth")):
        wrong = True if motion.get(False) is not None else False if motion.get(True) is not None else None
        _refuse(path, "depth", pair["depth"], wrong, cols, units)


def _values(ch):
    return ch.values if ch.valid is None else np.where(ch.valid, ch.values, np.nan)


def _refuse(path, kind, s, wrong, cols, units):
    """A sensor and its reference ``s`` times apart: refuse naming the wrong one (``wrong``: True
    the reference, False the sensor, None unknown: both)."""
    sensor, other = cols[(False, kind)], cols[(True, kind)]
    text = f"{other} is {abs(s):.3g} x {sensor} (least squares): "
    if wrong is None:
        raise DataError(path, f"columns {sensor} and {other}: {text}the declared units of the two disagree")
    col, unit = cols[(wrong, kind)], units[(wrong, kind)]
    guess = likely_unit(kind, unit, abs(s) if wrong else 1 / abs(s))
    raise DataError(
        path, f"column {col}: {text}{col} is not in {unit}" + (f" (it looks like {guess})" if guess else "")
    )
