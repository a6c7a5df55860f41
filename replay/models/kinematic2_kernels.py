"""2-D kinematic model of the fusion task, once (:class:`replay.models.kinematic.Kinematic2D`).

State ``[east, north, yaw, u, v, r]``, ``p_f = [dt]``::

    east_k  = east + (u cos yaw - v sin yaw) dt      yaw_k = wrap(yaw + r dt)
    north_k = north + (u sin yaw + v cos yaw) dt     u, v, r constant
"""

from __future__ import annotations

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np

from replay.models.kinematic_select import H, h  # noqa: F401 (the module's measurement kernels)
from replay.util.kernels import wrap_angle  # replay.util.angles.wrap, compiled


@nb.njit(cache=True)
def f(x, p, out):
    dt = p[0]
    c, s = np.cos(x[2]), np.sin(x[2])
    out[0] = x[0] + (x[3] * c - x[4] * s) * dt
    out[1] = x[1] + (x[3] * s + x[4] * c) * dt
    out[2] = wrap_angle(x[2] + x[5] * dt)
    out[3], out[4], out[5] = x[3], x[4], x[5]


@nb.njit(cache=True)
def F(x, p, J):
    dt = p[0]
    c, s = np.cos(x[2]), np.sin(x[2])
    for i in range(6):
        for j in range(6):
            J[i, j] = 1.0 if i == j else 0.0
    J[0, 2], J[0, 3], J[0, 4] = (-x[3] * s - x[4] * c) * dt, c * dt, -s * dt
    J[1, 2], J[1, 3], J[1, 4] = (x[3] * c - x[4] * s) * dt, s * dt, c * dt
    J[2, 5] = dt
