"""Elementary functions for numba kernels (model kernels and :mod:`replay.filters.compiled`).

:func:`atan2` agrees with the C library's to about one unit in the last place
(``tests/test_kernel_math.py`` checks 2 ulp on a million random pairs and the
special cases) at a third of its cost: bearings and elevations are most of the
transcendental work of the sonar filters (two per measurement prediction).

Method: with r = min(|x|, |y|) / max(|x|, |y|) in [0, 1], take the table point
c = k / 64 nearest to r and atan(r) = atan(c) + atan(t), t = (r - c) / (1 + r c),
|t| <= 1/128, where atan(t) = t - t^3/3 + ... + t^9/9 is exact to rounding
(the next term is below 1e-24). Then the octant: pi/2 - a when |y| > |x|,
pi - a when x < 0, the sign of y. Zeros, infinities and NaN go to the C library.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

ATAN_TABLE = np.array([math.atan(k / 64.0) for k in range(65)])
HALF_PI = 0.5 * math.pi
INF = math.inf


@nb.njit(cache=True)
def atan_unit(r):
    """atan(r) for 0 <= r <= 1."""
    k = int(r * 64.0 + 0.5)
    c = k * (1.0 / 64.0)
    t = (r - c) / (1.0 + r * c)
    t2 = t * t
    p = t2 * (1.0 / 3.0 - t2 * (1.0 / 5.0 - t2 * (1.0 / 7.0 - t2 * (1.0 / 9.0))))
    return ATAN_TABLE[k] + (t - t * p)


@nb.njit(cache=True)
def atan2(y, x):
    """The angle of (x, y) in [-pi, pi], as ``numpy.arctan2(y, x)``."""
    ax, ay = abs(x), abs(y)
    if not (0.0 < ax < INF and 0.0 < ay < INF):
        return np.arctan2(y, x)
    if ay <= ax:
        a = atan_unit(ay / ax)
    else:
        a = HALF_PI - atan_unit(ax / ay)
    if x < 0.0:
        a = math.pi - a
    return a if y > 0.0 else -a
