"""replay.kernel_math against the C library."""
from __future__ import annotations

import math

import numba
import numpy as np

from replay.kernel_math import atan2


@numba.njit
def many(y, x, out):
    for i in range(len(y)):
        out[i] = atan2(y[i], x[i])


def ulps(a, b):
    return np.abs(a - b) / np.spacing(np.maximum(np.abs(a), np.abs(b)))


def test_atan2_within_two_ulp_of_libm():
    g = np.random.default_rng(0)
    n = 1_000_000
    mag = 10.0 ** g.uniform(-8, 8, (2, n))
    y, x = mag * g.choice([-1.0, 1.0], (2, n))
    x[:1000] = y[:1000] * g.uniform(0.999, 1.001, 1000)  # near the octant edges
    out = np.empty(n)
    many(y, x, out)
    assert ulps(out, np.arctan2(y, x)).max() <= 2.0


def test_atan2_special_cases_are_the_c_librarys():
    cases = [(0.0, 1.0), (-0.0, 1.0), (0.0, -1.0), (-0.0, -1.0), (0.0, 0.0), (-0.0, -0.0), (1.0, 0.0),
             (-1.0, -0.0), (math.inf, 1.0), (1.0, -math.inf), (math.inf, -math.inf), (math.nan, 1.0),
             (1.0, math.nan), (1e-320, 1.0), (1.0, 1e-320), (3.0, 3.0), (-3.0, -3.0)]
    y = np.array([c[0] for c in cases])
    x = np.array([c[1] for c in cases])
    out = np.empty(len(cases))
    many(y, x, out)
    ref = np.arctan2(y, x)
    assert np.array_equal(np.isnan(out), np.isnan(ref))
    ok = ~np.isnan(ref)
    assert np.all(np.signbit(out[ok]) == np.signbit(ref[ok]))
    assert ulps(out[ok], ref[ok]).max() <= 2.0
