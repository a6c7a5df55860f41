"""Univariate nonstationary growth model (UNGM), paper 002 §3.2: the model's equations, once.

The numba kernels of one state of :class:`replay.models.ungm.UNGM` (see
:mod:`replay.models.kernel_model`); the model's array methods are derived from them.

    x_k = 0.5 x_{k-1} + g x_{k-1} / (1 + x_{k-1}^2) + 8 cos(1.2 k) + w_k,   w ~ N(0, Q)
    z_k = x_k^2 / 20 + v_k,                                                  v ~ N(0, R)

with g = 2.5 as printed in 002 (and its digest). The classic UNGM of the
particle-filter literature (Kitagawa 1996; Gordon et al. 1993) has g = 25:
``growth=25`` gives it. Time: step ``k`` of a run (0-based) is model time
``k + k0`` (``k0 = 1``: the first measurement is z_1, the prior x_0 = 0).

Parameters: ``p_f = [g, 8 cos(1.2 (k + k0))]`` (the time term computed once per
step, by :meth:`UNGM.kernel_params`), ``p_h`` empty.
"""

from __future__ import annotations

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed


@nb.njit(cache=True)
def f(x, p, out):
    """x_k = 0.5 x + g x / (1 + x^2) + 8 cos(1.2 k)."""
    out[0] = 0.5 * x[0] + p[0] * x[0] / (1.0 + x[0] * x[0]) + p[1]


@nb.njit(cache=True)
def F(x, p, J):
    """df/dx = 0.5 + g (1 - x^2) / (1 + x^2)^2."""
    x2 = x[0] * x[0]
    J[0, 0] = 0.5 + p[0] * (1.0 - x2) / (1.0 + x2) ** 2


@nb.njit(cache=True)
def h(x, p, out):
    """z = x^2 / 20."""
    out[0] = x[0] * x[0] / 20.0


@nb.njit(cache=True)
def H(x, p, J):
    """dh/dx = x / 10."""
    J[0, 0] = x[0] / 10.0
