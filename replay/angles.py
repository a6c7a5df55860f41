"""Angle arithmetic on arrays.

Every angle in ``replay`` is in radians. Residuals between angles are wrapped to
[-pi, pi) and means of angles are circular means, so a set of sigma points or
particles that straddles +-pi averages to +-pi and not to 0 (the failure of
averaging raw angles, seen in popular filter libraries).
"""
from __future__ import annotations

import numpy as np


def wrap(a):
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def residual(a, b, angles=()):
    """``a - b`` along the last axis, with components listed in ``angles`` wrapped."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    if len(angles):
        d = d.copy() if d.base is not None else d
        idx = list(angles)
        d[..., idx] = wrap(d[..., idx])
    return d


def weighted_mean(x, w, angles=()):
    """Weighted mean of ``x`` (points along axis -2, components along -1).

    ``w`` has shape ``(n_points,)`` and sums to one (weights may be negative, as
    for scaled unscented points). Angle components get the circular mean
    ``atan2(sum w sin, sum w cos)``.
    """
    x = np.asarray(x, dtype=float)
    m = np.einsum("...ij,i->...j", x, w)
    if len(angles):
        idx = list(angles)
        s = np.einsum("...ij,i->...j", np.sin(x[..., idx]), w)
        c = np.einsum("...ij,i->...j", np.cos(x[..., idx]), w)
        m[..., idx] = np.arctan2(s, c)
    return m
