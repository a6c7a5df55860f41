"""Numba kernels of :class:`replay.models.auv_sonar.AUVSonar` for one state (see ``Model.kernels``).

The same arithmetic as the model's numpy ``f``, ``h``, ``F``, ``H``, written
for one state ``x`` (6,) with the parameters ``p_f = [T, yaw_rate]`` and
``p_h = origin`` (3,). ``tests/test_compiled.py`` asserts the agreement.
"""
from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def f(x, p, out):
    T, rate = p[0], p[1]
    v, th, ps = x[3], x[4], x[5]
    vc = v * np.cos(th) * T
    out[:] = x
    out[0] += vc * np.cos(ps)
    out[1] += vc * np.sin(ps)
    out[2] -= v * np.sin(th) * T
    out[5] += rate * T


@nb.njit(cache=True)
def F(x, p, J):
    T = p[0]
    v, th, ps = x[3], x[4], x[5]
    c, s, cp, sp = np.cos(th), np.sin(th), np.cos(ps), np.sin(ps)
    J[:] = 0.0
    for i in range(6):
        J[i, i] = 1.0
    J[0, 3], J[0, 4], J[0, 5] = c * cp * T, -v * s * cp * T, -v * c * sp * T
    J[1, 3], J[1, 4], J[1, 5] = c * sp * T, -v * s * sp * T, v * c * cp * T
    J[2, 3], J[2, 4] = -s * T, -v * c * T


@nb.njit(cache=True)
def h(x, p, out):
    dx, dy, dz = x[0] - p[0], x[1] - p[1], x[2] - p[2]
    rho2 = dx * dx + dy * dy
    rho = np.sqrt(rho2)
    out[0] = np.sqrt(rho2 + dz * dz)
    out[1] = np.arctan2(dz, rho)
    out[2] = np.arctan2(dy, dx)


@nb.njit(cache=True)
def H(x, p, J):
    dx, dy, dz = x[0] - p[0], x[1] - p[1], x[2] - p[2]
    rho2 = dx * dx + dy * dy
    r2 = rho2 + dz * dz
    J[:] = 0.0
    if r2 == 0.0 or rho2 == 0.0:  # at the sonar: bearing undefined, no information
        return
    r, rho = np.sqrt(r2), np.sqrt(rho2)
    J[0, 0], J[0, 1], J[0, 2] = dx / r, dy / r, dz / r
    J[1, 0], J[1, 1], J[1, 2] = -dx * dz / (r2 * rho), -dy * dz / (r2 * rho), rho / r2
    J[2, 0], J[2, 1] = -dy / rho2, dx / rho2
