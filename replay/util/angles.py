"""Angle arithmetic on arrays.

Every angle in ``replay`` is in radians. Residuals between angles are wrapped to
[-pi, pi) and means of angles are circular means, so a set of sigma points or
particles that straddles +-pi averages to +-pi and not to 0 (the failure of
averaging raw angles, seen in popular filter libraries).

``angles`` arguments are tuples of component indices (along the last axis).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

TWO_PI = 2.0 * np.pi
_INV_TWO_PI = 1.0 / TWO_PI


def wrap(a):
    """Wrap angles to [-pi, pi): a - floor(a / 2 pi + 0.5) 2 pi, of a number or an array (a new value).

    The project's one text of the angle wrap: numba compiles this same function for the kernels
    (:data:`replay.util.kernels.wrap_angle`), so compiled and plain Python wrap to the same bits.
    """
    return a - np.floor(a * _INV_TWO_PI + 0.5) * TWO_PI


@lru_cache(maxsize=256)
def index(angles: tuple[int, ...]):
    """A slice for contiguous component indices (cheaper to apply), else a list."""
    if angles and list(angles) == list(range(angles[0], angles[-1] + 1)):
        return slice(angles[0], angles[-1] + 1)
    return list(angles)


@lru_cache(maxsize=256)
def angle_mask(angles: tuple[int, ...], n: int) -> np.ndarray:
    """A read-only boolean mask (n,) of the components ``angles`` (for compiled kernels)."""
    m = np.zeros(n, dtype=np.bool_)
    m[list(angles)] = True
    m.flags.writeable = False
    return m


def residual(a, b, angles=()):
    """``a - b`` along the last axis, with components listed in ``angles`` wrapped."""
    return wrap_components(np.subtract(a, b, dtype=float), angles)


def wrap_components(x, angles=()):
    """Wrap the angle components of ``x`` in place and return it."""
    if angles:
        if x.ndim == 1:  # one vector: a Python loop beats numpy's per-call overhead
            for i in angles:
                x[i] = wrap(x[i])
        elif x.ndim == 2 and len(x) == 1:  # a stack of one vector (one run): the same, same bits
            v = x[0]
            for i in angles:
                v[i] = wrap(v[i])
        else:
            i = index(tuple(angles))
            a = x[..., i]
            # |a| < 3 (< pi - 0.14): floor(a / 2 pi + 0.5) = 0 exactly, so wrap(a) is a itself;
            # one cheap test skips the wrap of small residuals (sigma points, particles)
            if not (a.size and np.abs(a).max() < 3.0):
                x[..., i] = wrap(a)
    return x


def weighted_mean(x, w, angles=()):
    """Weighted mean of ``x`` (points along axis -2, components along -1).

    ``w`` has shape ``(n_points,)`` and sums to one (weights may be negative, as
    for scaled unscented points). Angle components get the circular mean
    ``atan2(sum w sin, sum w cos)``. ``x`` may carry leading axes (a stack of
    Monte Carlo runs): one matrix product per stacked slice, so each slice gets
    the numbers it gets alone.
    """
    m = w @ x
    if angles:
        i = index(tuple(angles))
        xa = x[..., i]
        m[..., i] = np.arctan2(w @ np.sin(xa), w @ np.cos(xa))
    return m
