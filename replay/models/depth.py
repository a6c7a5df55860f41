"""Depth, speed and pitch of a maneuvering AUV from its own sensors (paper 000, §2.1).

State x = [z, v, phi] (depth m positive down, speed m/s, pitch rad positive
nose down, so that a positive pitch makes the depth grow). Motion (eq. 4):

    z_k   = z_{k-1} + (v_{k-1} + u^v_k) sin(phi_{k-1} + u^phi_k) T + u^z_k
    v_k   = v_{k-1} + u^v_k
    phi_k = phi_{k-1} + u^phi_k,            u_k = [u^z, u^v, u^phi] ~ N(0, Q)

Measurement (eq. 6): z_k = x_k + w_k, w_k ~ N(0, R_k) (all three states measured).

* :meth:`DepthModel.sample_f` draws u and applies eq. 4 exactly (the same u^v,
  u^phi enter the depth and the speed/pitch rows), for particle filters.
* ``f`` is eq. 4 with u = 0 and ``F`` its Jacobian; Kalman filters treat the
  process noise as additive with covariance Q. The neglected part of the
  depth noise, (sin(phi) T)^2 Q_vv + (v cos(phi) T)^2 Q_phiphi, is below
  0.006 m^2 at T = 0.05 s, v < 2 m/s with the paper's Q, against Q_zz = 0.04 m^2.

Parameters (§3): T = 0.05 s; Q as printed, [[0.2^2, 0.8^2, 0.6^2], [0.8^2, 1^2, 0],
[0.6^2, 0, 0.5^2]], is not positive definite (determinant -0.22), so
:func:`paper_Q` returns diag(0.2^2, 1^2, 0.5^2) instead, as the digest asks;
EKF and MMPF use the fixed R = diag(0.2^2, 5^2, 0.5^2). The units of the
printed numbers are not stated; they are read in the frame's SI units
(metres, m/s, radians), which makes the pitch noise large (0.5 rad = 29 deg).
"""

from __future__ import annotations

import numpy as np

from replay.util.linalg import cholesky
from replay.model import Model, is_diagonal

T_PAPER = 0.05
Q_PRINTED = np.array([[0.2**2, 0.8**2, 0.6**2], [0.8**2, 1.0**2, 0.0], [0.6**2, 0.0, 0.5**2]])
Q_FALLBACK = np.diag([0.2**2, 1.0**2, 0.5**2])
R_FIXED = np.diag([0.2**2, 5.0**2, 0.5**2])


def is_positive_definite(M: np.ndarray) -> bool:
    M = np.asarray(M, float)
    return bool(np.allclose(M, M.T) and np.all(np.linalg.eigvalsh(M) > 0))


def paper_Q() -> tuple[np.ndarray, str]:
    """The process covariance to use and why: the print if positive definite, else the fallback."""
    if is_positive_definite(Q_PRINTED):
        return Q_PRINTED.copy(), "as printed (positive definite)"
    det = float(np.linalg.det(Q_PRINTED))
    return Q_FALLBACK.copy(), (
        f"printed Q is not positive definite (determinant {det:.4f}); using diag(0.2^2, 1^2, 0.5^2)"
    )


class DepthModel(Model):
    """Eq. 4 motion and eq. 6 measurement; ``dt`` scalar or one step length per sample."""

    nx, nz = 3, 3
    x_angles = (2,)
    z_angles = (2,)
    components = ("depth", "speed", "pitch")

    def __init__(self, Q=None, R=R_FIXED, dt=T_PAPER):
        self.Q = paper_Q()[0] if Q is None else np.asarray(Q, float)
        self.R = np.asarray(R, float)
        self.dt = np.asarray(dt, float)
        self.refresh_noise()

    def refresh_noise(self) -> None:
        """Recompute the factor of ``self.Q`` that :meth:`sample_f` draws with (after Q changed:
        a filter's own noise settings, :mod:`replay.filters.noise_params`)."""
        self._LQ = cholesky(self.Q)
        self._Qdiag = is_diagonal(self.Q)

    def step(self, k: int) -> float:
        """T for step k (seconds)."""
        return float(self.dt) if self.dt.ndim == 0 else float(self.dt[k])

    def f(self, x, k):
        y = np.array(x, dtype=float, copy=True)
        y[..., 0] += x[..., 1] * np.sin(x[..., 2]) * self.step(k)
        return y

    def F(self, x, k):
        T = self.step(k)
        J = np.eye(3)
        J[0, 1] = np.sin(x[2]) * T
        J[0, 2] = x[1] * np.cos(x[2]) * T
        return J

    def h(self, x, k):
        return np.array(x, dtype=float, copy=True)

    def H(self, x, k):
        return np.eye(3)

    def draw_noise(self, shape, rng) -> np.ndarray:
        e = rng.standard_normal((*shape, 3))
        return e * np.sqrt(np.diagonal(self.Q)) if self._Qdiag else e @ self._LQ.T

    def sample_f(self, x, k, rng):
        """Eq. 4 with u ~ N(0, Q) drawn for every state of ``x``."""
        u = self.draw_noise(x.shape[:-1], rng)
        return self.apply(x, u, k)

    def apply(self, x, u, k):
        """Eq. 4 for given noise ``u`` (same shape as ``x``)."""
        v = x[..., 1] + u[..., 1]
        phi = x[..., 2] + u[..., 2]
        y = np.empty(np.shape(x))
        y[..., 0] = x[..., 0] + v * np.sin(phi) * self.step(k) + u[..., 0]
        y[..., 1] = v
        y[..., 2] = phi
        return y
