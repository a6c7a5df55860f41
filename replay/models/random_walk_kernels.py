"""Random-walk position model observed directly (the Bohai experiment of paper 002), once.

    x_k = x_{k-1} + w_k,  w ~ N(0, Q);   z_k = x_k + v_k,  v ~ N(0, R):

f = h = identity, F = H = I. The numba kernels of one state of
:class:`replay.models.random_walk.RandomWalkPosition` (see
:mod:`replay.models.kernel_model`); no parameters (``p_f``, ``p_h`` empty).
"""

from __future__ import annotations

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed


@nb.njit(cache=True)
def identity(x, p, out):
    """out = x."""
    for i in range(x.shape[0]):  # element loops, not slice assignments: several times faster per state
        out[i] = x[i]


@nb.njit(cache=True)
def unit(x, p, J):
    """J = I."""
    for i in range(J.shape[0]):
        for j in range(J.shape[1]):
            J[i, j] = 0.0
        J[i, i] = 1.0


f = h = identity
F = H = unit
