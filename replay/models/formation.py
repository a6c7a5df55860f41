"""Follower UAV ranging a leader: paper 003, eq. 1–6.

State of the follower ``x = [x, y, vx, vy]`` (m, m/s; x east, y north).
Coordinated turn with known turn rate w_k (eq. 3; w > 0 left, w < 0 right,
w = 0 straight), step T:

    F(w) = [[1, 0, sin(wT)/w, (cos(wT) − 1)/w],
            [0, 1, (1 − cos(wT))/w, sin(wT)/w],
            [0, 0, cos(wT), −sin(wT)],
            [0, 0, sin(wT), cos(wT)]]

The paper prints F with sin(w)/w (i.e. T = 1 s) and the noise gain G (eq. 4)
as [[T²/2, 0], [T, 0], [0, T²/2], [0, T]], which is the gain of the state
order [x, vx, y, vy]; for our state order [x, y, vx, vy] it is
[[T²/2, 0], [0, T²/2], [T, 0], [0, T]]. Process noise w ~ N(0, Q_a), Q_a the
2×2 acceleration covariance, so the state's process covariance G Q_a Gᵀ is
singular (rank 2); :meth:`sample_f` draws through G.

Measurement (eq. 5–6) of the leader at the known position (x_l, y_l) (the
leader broadcasts its GPS/INS position):

    r = sqrt((x_l − x)² + (y_l − y)²),  b = atan2(y_l − y, x_l − x)

(the paper writes arctan((y_l − y)/(x_l − x)); atan2 keeps the quadrant).
The noise is ``noise`` (e.g. :class:`replay.models.noise.Glint`, eq. 7–10): the PF
likelihood is its density, and R = its covariance for the Kalman family.

A filter's noise settings (``q_scale``, ``r_scale``, ``Q``, ``R``:
:mod:`replay.filters.noise_params`) reach :meth:`sample_f` and :meth:`loglik`
through :meth:`refresh_noise`: Q must stay of the form G Q_a Gᵀ (q_scale
scales Q_a), R a multiple of the model's (r_scale scales both components of
the glint, so its covariance is R); any other Q or R is refused (one line).
"""

from __future__ import annotations

import numpy as np

from replay.util.angles import residual
from replay.util.errors import ReplayError
from replay.model import Model


def gain(T: float) -> np.ndarray:
    return np.array([[T * T / 2, 0.0], [0.0, T * T / 2], [T, 0.0], [0.0, T]])


def transition(w: float, T: float) -> np.ndarray:
    if abs(w) < 1e-12:
        return np.array([[1.0, 0, T, 0], [0, 1.0, 0, T], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
    s, c = np.sin(w * T), np.cos(w * T)
    return np.array([[1.0, 0, s / w, (c - 1) / w], [0, 1.0, (1 - c) / w, s / w], [0, 0, c, -s], [0, 0, s, c]])


class Formation(Model):
    nx, nz = 4, 2
    z_angles = (1,)
    components = ("x", "y", "vx", "vy")

    def __init__(self, leader, turn_rate, T: float = 1.0, Qa=np.eye(2), noise=None, R=None):
        self.leader = np.asarray(leader, float)  # (n, 2)
        self.turn_rate = np.broadcast_to(np.asarray(turn_rate, float), (len(self.leader),))
        self.T = float(T)
        self.Qa = np.asarray(Qa, float)
        self.G = gain(self.T)
        self.Q = self.G @ self.Qa @ self.G.T
        self.noise = noise
        self.R = np.asarray(R, float) if R is not None else noise.cov
        self._F = [transition(w, self.T) for w in self.turn_rate]
        self._La = np.linalg.cholesky(self.Qa)
        self._R0, self._noise0 = self.R.copy(), noise

    def refresh_noise(self) -> None:
        """After a filter's noise settings changed ``Q`` or ``R`` (module docstring): the acceleration
        covariance Q_a that :meth:`sample_f` draws with, and the glint noise scaled with R."""
        Gp = np.linalg.pinv(self.G)
        Qa = Gp @ self.Q @ Gp.T
        if not np.allclose(self.G @ Qa @ self.G.T, self.Q, rtol=1e-9, atol=1e-12):
            raise ReplayError(
                "model Formation: Q must be G Q_a Gᵀ (the acceleration noise through the gain of "
                "eq. 4); change it with q_scale"
            )
        self.Qa, self._La = Qa, np.linalg.cholesky(Qa)
        s = float(self.R.flat[0] / self._R0.flat[0])
        if not np.allclose(self.R, s * self._R0, rtol=1e-9, atol=0):
            raise ReplayError(
                "model Formation: R must be a multiple of the glint noise's covariance; change it with r_scale"
            )
        n = self._noise0
        if n is not None:
            # a glint mixture (replay.models.noise.Glint) with both covariances times s: its covariance is R
            self.noise = n if s == 1.0 else type(n)(n.P1 * s, n.P2 * s, n.eps, n.mu1 * s**0.5, n.mu2 * s**0.5)

    def f(self, x, k):
        return x @ self._F[k].T

    def F(self, x, k):
        return self._F[k]

    def h(self, x, k):
        d = self.leader[k] - x[..., :2]
        return np.stack([np.hypot(d[..., 0], d[..., 1]), np.arctan2(d[..., 1], d[..., 0])], axis=-1)

    def sample_f(self, x, k, rng):
        e = rng.standard_normal(x.shape[:-1] + (2,)) @ self._La.T
        return self.f(x, k) + e @ self.G.T

    def loglik(self, z, x, k, mask=None):
        if self.noise is None or mask is not None:
            return super().loglik(z, x, k, mask)
        return self.noise.logpdf(residual(z, self.h(x, k), self.z_angles))
