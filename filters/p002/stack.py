"""Angle helpers of the paper-002 numpy code (the PSO move and the likelihood of :mod:`replay.filters.p002`).

Both act on stacks (leading axes: runs, particles) at once:
:func:`wrap_inplace`, :func:`fast_residual` — :func:`replay.util.angles.wrap`
and :func:`replay.util.angles.residual` bit for bit, without temporaries: the
same operations (x - floor(x / 2 pi + 0.5) 2 pi) in one compiled pass over a
contiguous stack (:func:`replay.filters.p002.compiled_util.wrap_rows`; a numpy
pass over the angle columns was a fifth of PSO-PF's time), in numpy otherwise.
(The stacked Cholesky, solve and circular mean of the former numpy cubature
engine live in the test oracle ``tests/oracle_p002.py``.)
"""

from __future__ import annotations

import numpy as np

from replay.util.angles import angle_mask, index, wrap

from .compiled_util import wrap_rows
from ..compiled import Kernel

_wrap_rows = Kernel(wrap_rows)


def wrap_inplace(x, angles):
    """Wrap the ``angles`` components of ``x`` in place: the arithmetic of
    :func:`replay.util.angles.wrap` (bit for bit) without its temporaries. Returns ``x``."""
    if angles and x.dtype == np.float64 and x.flags.c_contiguous and x.ndim and x.size:
        n = x.shape[-1]
        _wrap_rows(x.reshape(-1, n), angle_mask(tuple(angles), n))
    elif angles:
        x[..., index(tuple(angles))] = wrap(x[..., index(tuple(angles))])
    return x


def fast_residual(a, b, angles):
    """``a - b`` with the ``angles`` components wrapped; equals :func:`replay.util.angles.residual`."""
    return wrap_inplace(np.subtract(a, b), angles)
