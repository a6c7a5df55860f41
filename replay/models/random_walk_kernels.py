"""Numba kernels of :class:`replay.models.random_walk.RandomWalkPosition` (f = h = identity)."""
from __future__ import annotations

import numba as nb


@nb.njit(cache=True)
def identity(x, p, out):
    out[:] = x


@nb.njit(cache=True)
def unit(x, p, J):
    J[:, :] = 0.0
    for i in range(J.shape[0]):
        J[i, i] = 1.0
