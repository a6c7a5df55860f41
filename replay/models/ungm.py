"""Univariate nonstationary growth model (UNGM): paper 002, §3.2 (benchmark 1 for GWO vs IGWO).

The equations are written once, as the kernels of
:mod:`replay.models.ungm_kernels` (whose docstring gives them, with the growth
coefficient as printed in 002 and the time convention); ``f``, ``h``, ``F``,
``H`` on arrays of states (..., 1) are derived from them
(:mod:`replay.models.kernel_model`).
"""

from __future__ import annotations

import numpy as np

from replay.models.kernel_model import KernelModel


class UNGM(KernelModel):
    """x_k = 0.5 x + g x / (1 + x^2) + 8 cos(1.2 (k + k0)) + w,  z = x^2 / 20 + v."""

    nx = nz = 1
    components = ("x",)
    kernel_module = "replay.models.ungm_kernels"

    def __init__(self, Q=1.0, R=1.0, growth: float = 2.5, k0: int = 1):
        self.Q = np.atleast_2d(np.asarray(Q, float))
        self.R = np.atleast_2d(np.asarray(R, float))
        self.growth, self.k0 = float(growth), int(k0)

    def kernel_params(self, k):
        """``p_f = [g, 8 cos(1.2 (k + k0))]``, ``p_h`` empty."""
        return np.array([self.growth, 8.0 * np.cos(1.2 * (k + self.k0))]), np.empty(0)
