"""Where a drawn series breaks: NaN samples and time gaps (a step above :data:`GAP` times the median
step) break a line instead of being bridged (:func:`gaps`); a sparse track (a recorded estimate, NaN
on every reference sample it was not associated with) is drawn through its finite samples, broken
only at its own time gaps (:func:`joined`), and so is any series whose finite samples are mostly
isolated (:func:`line`: a reference held only at GPS fixes). Used by the report (:mod:`replay.outputs.plots`) and the
Python API's figures (:mod:`replay.run.plots`). Imports nothing of replay.
"""

from __future__ import annotations

import numpy as np

GAP = 5.0  # a time step above GAP x the median step is a gap in the data: lines break there


def gaps(t, *ys, factor: float = GAP):
    """``t`` and each ``y`` (along its last axis) with a NaN inserted inside every time gap."""
    t = np.asarray(t, float)
    ys = [np.asarray(y, float) for y in ys]
    dt = np.diff(t)
    ok = np.isfinite(dt) & (dt > 0)
    if not ok.any():
        return (t, *ys)
    at = np.flatnonzero(dt > factor * np.median(dt[ok])) + 1
    if not len(at):
        return (t, *ys)
    t = np.insert(t, at, np.nan)
    return (t, *(np.insert(y, at, np.nan, axis=-1) for y in ys))


def joined(t, *ys, factor: float = GAP):
    """The samples where ``t`` and every ``y`` (along its last axis) are finite, with a NaN inserted
    inside each of their time gaps (:func:`gaps`): a sparse track's associated points as one line."""
    t = np.asarray(t, float)
    ys = [np.asarray(y, float) for y in ys]
    keep = np.isfinite(t)
    for y in ys:
        keep &= np.isfinite(y).reshape(-1, len(t)).all(axis=0)
    return gaps(t[keep], *(y[..., keep] for y in ys), factor=factor)


def isolated(finite) -> bool:
    """Whether most of the ``True`` samples of ``finite`` have no ``True`` neighbour: a line through
    the samples as they lie would draw (nearly) nothing, e.g. a reference held only at GPS fixes on
    an IMU-rate time axis, or the errors scored there."""
    f = np.asarray(finite, bool)
    if f.sum() < 2:
        return False
    pad = np.r_[False, f, False]
    alone = f & ~pad[:-2] & ~pad[2:]
    return bool(alone.sum() * 2 > f.sum())


def line(t, *ys, factor: float = GAP):
    """:func:`joined` when the samples finite in ``t`` and every ``y`` are mostly :func:`isolated`,
    else :func:`gaps` (NaN samples, e.g. a masked reference, break the line)."""
    t = np.asarray(t, float)
    ys = [np.asarray(y, float) for y in ys]
    keep = np.isfinite(t)
    for y in ys:
        keep &= np.isfinite(y).reshape(-1, len(t)).all(axis=0)
    return (joined if isolated(keep) else gaps)(t, *ys, factor=factor)
