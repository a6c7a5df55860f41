"""AUV tracked by a single active sonar (paper 002, benchmark 2): the model's equations, once.

The numba kernels of one state of :class:`replay.models.auv_sonar.AUVSonar`
(see :mod:`replay.models.kernel_model`): the compiled filters call them as they
are, and the model's array methods ``f``, ``h``, ``F``, ``H`` are derived from
them. Parameters: ``p_f = [T, yaw_rate]``, ``p_h = origin`` (3,).

State ``x = [x, y, z, v, pitch, yaw]`` in the sonar's local ENU frame (metres,
m/s, radians; ``z`` positive up). Measurement (002, §1.2): range, elevation and
azimuth of the AUV from the sonar at ``origin``:

    r = sqrt(dx^2 + dy^2 + dz^2),  theta = atan2(dz, sqrt(dx^2 + dy^2)),  phi = atan2(dy, dx)

(the paper writes arctan(y/x); atan2 keeps the quadrant).

Motion: the paper only cites the kinematic transform (its eq. 1) and Table 2
(initial speed 10 m/s, pitch pi/4, yaw pi/10, yaw rate 0.25 rad/s, T = 1 s).
Our reading, documented here because the paper gives no transition equation:
constant speed and pitch, yaw turning at the known rate ``yaw_rate``,

    x += v cos(pitch) cos(yaw) T,  y += v cos(pitch) sin(yaw) T,
    z -= v sin(pitch) T            (pitch positive = nose down, so the AUV dives:
                                    the paper's PSO bounds keep z in [-300, 0])
    v, pitch unchanged,  yaw += yaw_rate T,

plus additive noise w ~ N(0, Q), Q = diag(1, 1, 1, 0.1, 0.01, 0.01).
"""

from __future__ import annotations

import math

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np


@nb.njit(cache=True)
def f(x, p, out):
    """The motion above: constant speed and pitch, yaw turning at ``yaw_rate``, over ``T``."""
    T, rate = p[0], p[1]
    v, th, ps = x[3], x[4], x[5]
    vc = v * np.cos(th) * T
    for i in range(6):  # element loops, not slice assignments: several times faster per state
        out[i] = x[i]
    out[0] += vc * np.cos(ps)
    out[1] += vc * np.sin(ps)
    out[2] -= v * np.sin(th) * T
    out[5] += rate * T


@nb.njit(cache=True)
def F(x, p, J):
    """Jacobian of f (6, 6)."""
    T = p[0]
    v, th, ps = x[3], x[4], x[5]
    c, s, cp, sp = np.cos(th), np.sin(th), np.cos(ps), np.sin(ps)
    for i in range(6):
        for j in range(6):
            J[i, j] = 0.0
        J[i, i] = 1.0
    J[0, 3], J[0, 4], J[0, 5] = c * cp * T, -v * s * cp * T, -v * c * sp * T
    J[1, 3], J[1, 4], J[1, 5] = c * sp * T, -v * s * sp * T, v * c * cp * T
    J[2, 3], J[2, 4] = -s * T, -v * c * T


@nb.njit(cache=True)
def h(x, p, out):
    """Range, elevation, azimuth of the AUV from the sonar at ``origin = p``."""
    dx, dy, dz = x[0] - p[0], x[1] - p[1], x[2] - p[2]
    rho2 = dx * dx + dy * dy  # sqrt, not hypot: cheaper, and no overflow at sonar ranges
    rho = np.sqrt(rho2)
    out[0] = np.sqrt(rho2 + dz * dz)
    out[1] = math.atan2(dz, rho)  # math, not np.arctan2: the same C library call when compiled, and
    out[2] = math.atan2(dy, dx)  # in plain Python too (NumPy's own arctan2 differs in the last bit)


@nb.njit(cache=True)
def H(x, p, J):
    """Jacobian of h (3, 6): zero where the AUV is at the sonar or straight above or below it
    (bearing undefined, no information)."""
    dx, dy, dz = x[0] - p[0], x[1] - p[1], x[2] - p[2]
    rho2 = dx * dx + dy * dy
    r2 = rho2 + dz * dz
    for i in range(3):
        for j in range(6):
            J[i, j] = 0.0
    if r2 == 0.0 or rho2 == 0.0:
        return
    r, rho = np.sqrt(r2), np.sqrt(rho2)
    J[0, 0], J[0, 1], J[0, 2] = dx / r, dy / r, dz / r
    J[1, 0], J[1, 1], J[1, 2] = -dx * dz / (r2 * rho), -dy * dz / (r2 * rho), rho / r2
    J[2, 0], J[2, 1] = -dy / rho2, dx / rho2
