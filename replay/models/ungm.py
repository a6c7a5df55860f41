"""Univariate nonstationary growth model (UNGM): paper 002, §3.2 (benchmark 1 for GWO vs IGWO).

    x_k = 0.5 x_{k-1} + g x_{k-1} / (1 + x_{k-1}^2) + 8 cos(1.2 k) + w_k,   w ~ N(0, Q)
    z_k = x_k^2 / 20 + v_k,                                                  v ~ N(0, R)

with g = 2.5 as printed in 002 (and its digest). The classic UNGM of the
particle-filter literature (Kitagawa 1996; Gordon et al. 1993) has g = 25:
``growth=25`` gives it. Time: step ``k`` of a run (0-based) is model time
``k + k0`` (``k0 = 1``: the first measurement is z_1, the prior x_0 = 0).
"""
from __future__ import annotations

import numpy as np

from replay.model import Model


class UNGM(Model):
    nx = nz = 1
    components = ("x",)
    vector_jacobians = True  # F and H also take stacks of states (..., 1)

    def __init__(self, Q=1.0, R=1.0, growth: float = 2.5, k0: int = 1):
        self.Q = np.atleast_2d(np.asarray(Q, float))
        self.R = np.atleast_2d(np.asarray(R, float))
        self.growth, self.k0 = float(growth), int(k0)

    def kernels(self):
        from . import ungm_kernels as kern

        return kern.f, kern.h, kern.F, kern.H

    def kernel_params(self, k):
        return np.array([self.growth, 8.0 * np.cos(1.2 * (k + self.k0))]), np.empty(0)

    def f(self, x, k):
        return 0.5 * x + self.growth * x / (1.0 + x * x) + 8.0 * np.cos(1.2 * (k + self.k0))

    def F(self, x, k):
        """d f / d x at ``x`` (1,) -> (1, 1), or at a stack (..., 1) -> (..., 1, 1)."""
        x = np.asarray(x, float)[..., :1, None]
        return 0.5 + self.growth * (1.0 - x * x) / (1.0 + x * x) ** 2

    def h(self, x, k):
        return x * x / 20.0

    def H(self, x, k):
        return np.asarray(x, float)[..., :1, None] / 10.0
