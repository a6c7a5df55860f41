"""Numba kernels of :class:`replay.models.ungm.UNGM` for one state (see ``Model.kernels``).

``p_f = [g, 8 cos(1.2 (k + k0))]`` (the time term computed once per step), ``p_h`` empty.
"""
from __future__ import annotations

import numba as nb


@nb.njit(cache=True)
def f(x, p, out):
    out[0] = 0.5 * x[0] + p[0] * x[0] / (1.0 + x[0] * x[0]) + p[1]


@nb.njit(cache=True)
def F(x, p, J):
    x2 = x[0] * x[0]
    J[0, 0] = 0.5 + p[0] * (1.0 - x2) / (1.0 + x2) ** 2


@nb.njit(cache=True)
def h(x, p, out):
    out[0] = x[0] * x[0] / 20.0


@nb.njit(cache=True)
def H(x, p, J):
    J[0, 0] = x[0] / 10.0
