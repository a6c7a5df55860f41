"""AUV tracked by a single active sonar: paper 002 (IGWO-STCPF), benchmark 2.

The state, the measurement and the motion (our reading of the paper) are
written once, as the kernels of :mod:`replay.models.auv_sonar_kernels` (whose
docstring gives the equations); ``f``, ``h``, ``F``, ``H`` on arrays of states
are derived from them (:mod:`replay.models.kernel_model`). This module holds
the parameters and Table 2's covariances.
"""

from __future__ import annotations

import numpy as np

from replay.models.kernel_model import KernelModel

Q_TABLE2 = np.diag([1.0, 1.0, 1.0, 0.1, 0.01, 0.01])
R_TABLE2 = np.diag([2.0, 0.01**2, 0.01**2])
P0_TABLE2 = np.diag([1.0, 1.0, 1.0, 0.1, 0.01, 0.01])


class AUVSonar(KernelModel):
    """State ``[x, y, z, v, pitch, yaw]``, measurement ``[range, elevation, azimuth]``."""

    nx, nz = 6, 3
    x_angles = (4, 5)
    z_angles = (1, 2)
    components = ("x", "y", "z", "v", "pitch", "yaw")
    kernel_module = "replay.models.auv_sonar_kernels"

    def __init__(self, Q=Q_TABLE2, R=R_TABLE2, dt=1.0, yaw_rate=0.25, origin=(0.0, 0.0, 0.0)):
        self.Q = np.asarray(Q, float)
        self.R = np.asarray(R, float)
        self.dt = np.asarray(dt, float)  # scalar, or one step length per sample
        self.yaw_rate = float(yaw_rate)
        self.origin = np.asarray(origin, float)

    def _dt(self, k):
        return float(self.dt) if self.dt.ndim == 0 else float(self.dt[k])

    def kernel_params(self, k):
        """``p_f = [T, yaw_rate]`` (T the step length ending at sample k), ``p_h = origin``."""
        return np.array([self._dt(k), self.yaw_rate]), self.origin
