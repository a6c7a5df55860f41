"""Kinematic vehicle models of the ``fusion`` task: constant body velocity and body rates.

In the spirit of robot_localization's ``ekf_localization_node`` (its 2-D mode and its
full 3-D state without accelerations), on the frame's own, irregular time axis:

**2-D** (``Kinematic2D``), state ``x = [east, north, yaw, u, v, r]`` — position (m, local
ENU), yaw (rad, anticlockwise from east, wrapped), body velocity forward ``u`` and left
``v`` (m/s), yaw rate ``r`` (rad/s)::

    east_k  = east + (u cos yaw - v sin yaw) dt      yaw_k = yaw + r dt
    north_k = north + (u sin yaw + v cos yaw) dt     u, v, r constant

**3-D** (``Kinematic3D``), state ``x = [east, north, up, roll, pitch, yaw, u, v, w, p, q, r]``
— REP-103 axes (body x forward, y left, z up; roll about x, pitch about y: positive
nose down, yaw about z), body velocity ``u, v, w`` and body rates ``p, q, r``::

    position_k = position + R(roll, pitch, yaw) [u, v, w] dt,  R = Rz(yaw) Ry(pitch) Rx(roll)
    roll_k  = roll + (p + (q sin roll + r cos roll) tan pitch) dt
    pitch_k = pitch + (q cos roll - r sin roll) dt
    yaw_k   = yaw + (q sin roll + r cos roll) / cos pitch dt     (the Euler-angle rates)

Process noise ``Q_k = diag(q) dt`` (per-second spectral densities, random walks on the
velocities and rates). Measurements select state components, with a sign (depth = -up):
``h(x) = x[:, index] * sign`` — linear, ``H`` a signed selection matrix. The measurement
covariance may change from step to step (recorded per-message covariances):
``measurement_cov(k)``.

The equations are written once, as numba kernels of one state
(:mod:`replay.models.kinematic2_kernels`, :mod:`replay.models.kinematic3_kernels`,
:mod:`replay.models.kinematic_select`); the array methods are derived from them
(:mod:`replay.models.kernel_model`), and the compiled filters of paper 002 run on them.
"""

from __future__ import annotations

import numpy as np

from replay.models.kernel_model import KernelModel


class Kinematic(KernelModel):
    """Shared part: the measurement selection and the time-varying Q and R."""

    STATE: tuple = ()
    ANGLES: tuple = ()
    mean_at_f = True  # a dead-reckoned pose: the sigma-point filters' predicted mean is f(mean)

    def __init__(self, dt, q, index, sign, z_angles, R_steps):
        self.nx, self.nz = len(self.STATE), len(index)
        self.x_angles = tuple(self.ANGLES)
        self.z_angles = tuple(z_angles)
        self.dt = np.asarray(dt, float)
        self.q = np.asarray(q, float)
        self.index = np.asarray(index, int)
        self.sign = np.asarray(sign, float)
        self._p_h = np.concatenate([[len(index)], self.index, self.sign]).astype(float)
        self._p_f = self.dt.reshape(-1, 1).copy()  # p_f of step k: [dt_k]
        self.R_steps = np.asarray(R_steps, float)  # (n, nz) variances per step
        self.R = np.diag(np.nanmedian(self.R_steps, axis=0)) if len(self.R_steps) else np.eye(self.nz)
        self.Q = np.diag(self.q * max(float(np.median(self.dt)) if len(self.dt) else 1.0, 1e-6))

    def kernel_params(self, k):
        return self._p_f[k], self._p_h

    def selection(self):
        """``(index, sign)``: h(x) = sign * x[index], Q and R diagonal at every step (what the
        particle filter's optimal proposal needs: :func:`replay.filters.particles.propose`)."""
        return self.index, self.sign

    def process_cov(self, k):
        return np.diag(self.q * max(self.dt[k], 1e-9))

    def measurement_cov(self, k):
        return np.diag(self.R_steps[k])

    def process_covs(self, steps):
        """``process_cov(k)`` of the first ``steps`` steps, one stack (steps, nx, nx) (the run loops')."""
        return _diagonals(self.q * np.maximum(self.dt[:steps], 1e-9)[:, None])

    def measurement_covs(self, steps):
        """``measurement_cov(k)`` of the first ``steps`` steps, one stack (steps, nz, nz)."""
        return _diagonals(self.R_steps[:steps])


def _diagonals(d):
    """(steps, n, n) diagonal matrices of the rows of ``d`` (steps, n)."""
    out = np.zeros(d.shape + d.shape[-1:])
    i = np.arange(d.shape[-1])
    out[:, i, i] = d
    return out


class Kinematic2D(Kinematic):
    STATE = ("east", "north", "yaw", "u", "v", "r")
    ANGLES = (2,)
    kernel_module = "replay.models.kinematic2_kernels"


class Kinematic3D(Kinematic):
    STATE = ("east", "north", "up", "roll", "pitch", "yaw", "u", "v", "w", "p", "q", "r")
    ANGLES = (3, 4, 5)
    kernel_module = "replay.models.kinematic3_kernels"


def rotation(roll, pitch, yaw) -> np.ndarray:
    """(..., 3, 3) body-to-ENU rotations Rz(yaw) Ry(pitch) Rx(roll) (the differential inputs'
    rotation into the body frame; the model's own is in its kernels)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
            np.stack([-sp, cp * sr, cp * cr], -1),
        ],
        -2,
    )
