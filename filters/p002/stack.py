"""Angle helpers of the paper-002 numpy code (the PSO move and the likelihood of :mod:`replay.filters.p002`).

Both act on stacks (leading axes: runs, particles) at once:
:func:`wrap_inplace`, :func:`fast_residual` — :func:`replay.util.angles.wrap`
and :func:`replay.util.angles.residual` bit for bit, without temporaries.
(The stacked Cholesky, solve and circular mean of the former numpy cubature
engine live in the test oracle ``tests/oracle_p002.py``.)
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import TWO_PI, index


def wrap_inplace(x, angles):
    """Wrap the ``angles`` components of ``x`` in place: the arithmetic of
    :func:`replay.util.angles.wrap` (bit for bit) without its temporaries. Returns ``x``."""
    if angles:
        a = x[..., index(tuple(angles))]
        t = a * (1.0 / TWO_PI)
        t += 0.5
        np.floor(t, out=t)
        t *= TWO_PI
        a -= t
        if not isinstance(index(tuple(angles)), slice):  # fancy index: a is a copy
            x[..., index(tuple(angles))] = a
    return x


def fast_residual(a, b, angles):
    """``a - b`` with the ``angles`` components wrapped; equals :func:`replay.util.angles.residual`."""
    return wrap_inplace(np.subtract(a, b), angles)
