"""Random-walk position model observed directly: the Bohai experiment of paper 002.

x_k = x_{k-1} + w_k,  w ~ N(0, Q);   z_k = x_k + v_k,  v ~ N(0, R).
"""
from __future__ import annotations

import numpy as np

from replay.model import Model


class RandomWalkPosition(Model):
    """3-D (or n-D) position random walk with direct position measurements."""

    def __init__(self, Q, R):
        self.Q = np.asarray(Q, float)
        self.R = np.asarray(R, float)
        self.nx = self.nz = self.Q.shape[0]
        self._I = np.eye(self.nx)

    def kernels(self):
        from . import random_walk_kernels as kern

        return kern.identity, kern.identity, kern.unit, kern.unit

    def kernel_params(self, k):
        return np.empty(0), np.empty(0)

    def f(self, x, k):
        return x

    def h(self, x, k):
        return x

    def F(self, x, k):
        return self._I

    def H(self, x, k):
        return self._I
