"""3-D kinematic model of the fusion task, once (:class:`replay.models.kinematic.Kinematic3D`).

State ``[east, north, up, roll, pitch, yaw, u, v, w, p, q, r]`` (REP-103 body axes),
``p_f = [dt]``::

    position_k = position + R(roll, pitch, yaw) [u, v, w] dt,  R = Rz(yaw) Ry(pitch) Rx(roll)
    roll_k  = roll + (p + (q sin roll + r cos roll) tan pitch) dt
    pitch_k = pitch + (q cos roll - r sin roll) dt
    yaw_k   = yaw + (q sin roll + r cos roll) / cos pitch dt      (angles wrapped)

``F`` by central differences of ``f`` (step 1e-6, angle differences wrapped): the model's
Jacobian has no short closed form worth a second text of the equations.
"""

from __future__ import annotations

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np

from replay.models.kinematic_select import H, h  # noqa: F401 (the module's measurement kernels)

from replay.util.kernels import wrap_angle as _wrap  # replay.util.angles.wrap, compiled


@nb.njit(cache=True)
def f(x, p, out):
    dt = p[0]
    cr, sr = np.cos(x[3]), np.sin(x[3])
    cp, sp = np.cos(x[4]), np.sin(x[4])
    cy, sy = np.cos(x[5]), np.sin(x[5])
    u, v, w = x[6], x[7], x[8]
    out[0] = x[0] + (cy * cp * u + (cy * sp * sr - sy * cr) * v + (cy * sp * cr + sy * sr) * w) * dt
    out[1] = x[1] + (sy * cp * u + (sy * sp * sr + cy * cr) * v + (sy * sp * cr - cy * sr) * w) * dt
    out[2] = x[2] + (-sp * u + cp * sr * v + cp * cr * w) * dt
    a = x[10] * sr + x[11] * cr
    out[3] = _wrap(x[3] + (x[9] + a * sp / cp) * dt)
    out[4] = _wrap(x[4] + (x[10] * cr - x[11] * sr) * dt)
    out[5] = _wrap(x[5] + a / cp * dt)
    for i in range(6, 12):
        out[i] = x[i]


@nb.njit(cache=True)
def F(x, p, J):
    eps = 1e-6
    xp, xm = x.copy(), x.copy()
    fp, fm = np.empty(12), np.empty(12)
    for j in range(12):
        xp[j] = x[j] + eps
        xm[j] = x[j] - eps
        f(xp, p, fp)
        f(xm, p, fm)
        for i in range(12):
            d = fp[i] - fm[i]
            if 3 <= i <= 5:
                d = _wrap(d)
            J[i, j] = d / (2 * eps)
        xp[j] = x[j]
        xm[j] = x[j]
