"""AUV tracked by a single active sonar: paper 002 (IGWO-STCPF), benchmark 2.

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

import numpy as np

from replay.model import Model

Q_TABLE2 = np.diag([1.0, 1.0, 1.0, 0.1, 0.01, 0.01])
R_TABLE2 = np.diag([2.0, 0.01**2, 0.01**2])
P0_TABLE2 = np.diag([1.0, 1.0, 1.0, 0.1, 0.01, 0.01])


class AUVSonar(Model):
    nx, nz = 6, 3
    x_angles = (4, 5)
    z_angles = (1, 2)
    components = ("x", "y", "z", "v", "pitch", "yaw")
    vector_jacobians = True  # F and H also take stacks of states (..., nx)

    def __init__(self, Q=Q_TABLE2, R=R_TABLE2, dt=1.0, yaw_rate=0.25, origin=(0.0, 0.0, 0.0)):
        self.Q = np.asarray(Q, float)
        self.R = np.asarray(R, float)
        self.dt = np.asarray(dt, float)  # scalar, or one step length per sample
        self.yaw_rate = float(yaw_rate)
        self.origin = np.asarray(origin, float)

    def _dt(self, k):
        return float(self.dt) if self.dt.ndim == 0 else float(self.dt[k])

    def kernels(self):
        from . import auv_sonar_kernels as kern

        return kern.f, kern.h, kern.F, kern.H

    def kernel_params(self, k):
        return np.array([self._dt(k), self.yaw_rate]), self.origin

    def f(self, x, k):
        T = self._dt(k)
        v, th, ps = x[..., 3], x[..., 4], x[..., 5]
        vc = v * np.cos(th) * T
        y = x.copy()
        y[..., 0] += vc * np.cos(ps)
        y[..., 1] += vc * np.sin(ps)
        y[..., 2] -= v * np.sin(th) * T
        y[..., 5] += self.yaw_rate * T
        return y

    def F(self, x, k):
        """Jacobian of f at ``x`` (6,) -> (6, 6), or at a stack (..., 6) -> (..., 6, 6)."""
        T = self._dt(k)
        if np.ndim(x) == 1:  # one state: scalar arithmetic is cheaper
            v, th, ps = x[3], x[4], x[5]
            c, s, cp, sp = np.cos(th), np.sin(th), np.cos(ps), np.sin(ps)
            J = np.eye(6)
            J[0, 3:6] = [c * cp * T, -v * s * cp * T, -v * c * sp * T]
            J[1, 3:6] = [c * sp * T, -v * s * sp * T, v * c * cp * T]
            J[2, 3:5] = [-s * T, -v * c * T]
            return J
        v, th, ps = x[..., 3], x[..., 4], x[..., 5]
        c, s, cp, sp = np.cos(th), np.sin(th), np.cos(ps), np.sin(ps)
        J = np.zeros(np.shape(x)[:-1] + (6, 6))
        J[..., range(6), range(6)] = 1.0
        J[..., 0, 3], J[..., 0, 4], J[..., 0, 5] = c * cp * T, -v * s * cp * T, -v * c * sp * T
        J[..., 1, 3], J[..., 1, 4], J[..., 1, 5] = c * sp * T, -v * s * sp * T, v * c * cp * T
        J[..., 2, 3], J[..., 2, 4] = -s * T, -v * c * T
        return J

    def h(self, x, k):
        if self.origin.any():
            x = x[..., :3] - self.origin
        dx, dy, dz = x[..., 0], x[..., 1], x[..., 2]
        rho2 = dx * dx + dy * dy  # sqrt, not hypot: 4x cheaper, and no overflow at sonar ranges
        rho = np.sqrt(rho2)
        out = np.empty(x.shape[:-1] + (3,))
        np.sqrt(rho2 + dz * dz, out=out[..., 0])
        np.arctan2(dz, rho, out=out[..., 1])
        np.arctan2(dy, dx, out=out[..., 2])
        return out

    def H(self, x, k):
        """Jacobian of h at ``x`` (6,) -> (3, 6), or at a stack (..., 6) -> (..., 3, 6).

        Zero where the AUV is at the sonar (bearing undefined, no information).
        """
        if np.ndim(x) == 1:  # one state: scalar arithmetic is cheaper
            dx, dy, dz = x[:3] - self.origin
            rho2 = dx * dx + dy * dy
            r2 = rho2 + dz * dz
            J = np.zeros((3, 6))
            if r2 == 0.0 or rho2 == 0.0:
                return J
            r, rho = np.sqrt(r2), np.sqrt(rho2)
            J[0, :3] = [dx / r, dy / r, dz / r]
            J[1, :3] = [-dx * dz / (r2 * rho), -dy * dz / (r2 * rho), rho / r2]
            J[2, :2] = [-dy / rho2, dx / rho2]
            return J
        d = x[..., :3] - self.origin
        dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
        rho2 = dx * dx + dy * dy
        r2 = rho2 + dz * dz
        J = np.zeros(np.shape(x)[:-1] + (3, 6))
        bad = (r2 == 0.0) | (rho2 == 0.0)
        if np.all(bad):
            return J
        with np.errstate(divide="ignore", invalid="ignore"):
            r, rho = np.sqrt(r2), np.sqrt(rho2)
            J[..., 0, 0], J[..., 0, 1], J[..., 0, 2] = dx / r, dy / r, dz / r
            J[..., 1, 0], J[..., 1, 1], J[..., 1, 2] = -dx * dz / (r2 * rho), -dy * dz / (r2 * rho), rho / r2
            J[..., 2, 0], J[..., 2, 1] = -dy / rho2, dx / rho2
        if np.any(bad):
            J[bad] = 0.0
        return J
