"""Random-walk position model observed directly: the Bohai experiment of paper 002.

x_k = x_{k-1} + w_k,  w ~ N(0, Q);   z_k = x_k + v_k,  v ~ N(0, R). The kernels
are :mod:`replay.models.random_walk_kernels`; ``f``, ``h``, ``F``, ``H`` on
arrays of states are derived from them (:mod:`replay.models.kernel_model`).
"""

from __future__ import annotations

import numpy as np

from replay.models.kernel_model import KernelModel


class RandomWalkPosition(KernelModel):
    """3-D (or n-D) position random walk with direct position measurements."""

    kernel_module = "replay.models.random_walk_kernels"

    def __init__(self, Q, R):
        self.Q = np.asarray(Q, float)
        self.R = np.asarray(R, float)
        self.nx = self.nz = self.Q.shape[0]

    def kernel_params(self, k):
        return np.empty(0), np.empty(0)

    def linear_matrices(self):
        return np.eye(self.nx), np.eye(self.nx), self.Q, self.R
