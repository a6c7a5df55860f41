"""Sigma-point Kalman filters: the unscented (UKF) and cubature (CKF) filters.

Both approximate the Gaussian integrals of the Kalman recursion by a weighted
set of points ``X_i = x + L xi_i`` (``L`` the lower Cholesky factor of ``P``),
pushed through ``f`` and ``h`` as one array. For each step:

    predict   Y_i = f(X_i),  x- = sum wm_i Y_i,  P- = sum wc_i (Y_i - x-)(Y_i - x-)' + Q
    update    X_i from (x-, P-),  Z_i = h(X_i),  z^ = sum wm_i Z_i
              Pzz = sum wc_i (Z_i - z^)(Z_i - z^)',  Pxz = sum wc_i (X_i - x-)(Z_i - z^)'
              S = Pzz + R,  K = Pxz S^-1,  x = x- + K (z - z^),  P = P- - K S K'

Means of angle components are circular means and every deviation of an angle
component (``Y_i - x-``, ``Z_i - z^``, ``z - z^``) is wrapped to [-pi, pi).
Averaging raw angles instead makes a point cloud that straddles +-pi average
to about 0 — the reason a popular library's CKF diverges on the sonar-tracking
scenario of paper 002 (azimuth crossing pi).

The points are regenerated from (x-, P-) before the update, as in the CKF of
Arasaratnam & Haykin (2009) and the UKF of Wan & van der Merwe (2000) with
augmentation-free additive noise.
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import residual, weighted_mean, wrap_components
from replay.util.linalg import cholesky, gain
from replay.model import remap_indices

from .base import Filter


class SigmaPointFilter(Filter):
    """Shared predict/update; subclasses set the unit points ``xi`` (m, n) and weights."""

    def points(self, n: int):
        """Unit points (m, n), mean weights (m,), covariance weights (m,)."""
        raise NotImplementedError

    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        state.xi, state.wm, state.wc = self.points(state.model.nx)

    def _sigma(self, state, x, P):
        """Points x + L xi_i; their deviations L xi_i are kept in ``state.dev`` (no wrapping needed)."""
        state.dev = state.xi @ cholesky(P).T
        return x + state.dev

    def predict(self, state, k):
        m = state.model
        Y = m.f(self._sigma(state, state.x, state.P), k)
        x = weighted_mean(Y, state.wm, m.x_angles)
        D = residual(Y, x, m.x_angles)
        state.x = x
        state.P = (D.T * state.wc) @ D + m.process_cov(k)

    def innovation(self, state, z, k, mask):
        """Points, predicted measurement, and the two covariance sums (without R)."""
        m = state.model
        X = self._sigma(state, state.x, state.P)
        Z = m.h(X, k)
        R = m.measurement_cov(k)
        angles = m.z_angles
        if mask is not None:
            Z, z, R = Z[:, mask], z[mask], R[np.ix_(mask, mask)]
            angles = remap_indices(angles, mask)
        zh = weighted_mean(Z, state.wm, angles)
        Dz = residual(Z, zh, angles)
        Dx = state.dev  # X_i - x-, exactly
        W = state.wc[:, None] * Dz
        Pzz = Dz.T @ W
        Pxz = Dx.T @ W
        return residual(z, zh, angles), Pzz, Pxz, R

    def update(self, state, z, k, mask):
        y, Pzz, Pxz, R = self.innovation(state, z, k, mask)
        self.correct(state, y, Pzz + R, Pxz)

    def correct(self, state, y, S, Pxz):
        K = gain(S, Pxz)
        x = wrap_components(state.x + K @ y, state.model.x_angles)
        P = state.P - K @ Pxz.T  # K S K' = K Pxz'
        P += P.T
        P *= 0.5
        state.x, state.P = x, P


class UKF(SigmaPointFilter):
    """Unscented Kalman filter with scaled sigma points (van der Merwe 2004, eq. 3.11–3.12).

    lambda = alpha^2 (n + kappa) - n; points x, x +- sqrt(n + lambda) L_i;
    wm_0 = lambda / (n + lambda), wc_0 = wm_0 + 1 - alpha^2 + beta,
    wm_i = wc_i = 1 / (2 (n + lambda)).

    Defaults alpha = 0.5, beta = 2 (optimal for Gaussian priors), kappa = 0:
    small alpha (1e-3, often quoted) gives wm_0 near -1e6 and needless
    cancellation error; for Gaussian problems any alpha in (0, 1] is exact to
    second order.
    """

    name = "ukf"

    def __init__(self, alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0):
        self.alpha, self.beta, self.kappa = alpha, beta, kappa

    def points(self, n):
        lam = self.alpha**2 * (n + self.kappa) - n
        c = np.sqrt(n + lam)
        xi = np.vstack([np.zeros(n), c * np.eye(n), -c * np.eye(n)])
        wm = np.full(2 * n + 1, 0.5 / (n + lam))
        wc = wm.copy()
        wm[0] = lam / (n + lam)
        wc[0] = wm[0] + 1 - self.alpha**2 + self.beta
        return xi, wm, wc


class CKF(SigmaPointFilter):
    """Cubature Kalman filter, third-degree spherical-radial rule (Arasaratnam & Haykin 2009).

    2n points xi_i = sqrt(n) [+-e_i], equal weights 1 / (2n).
    """

    name = "ckf"

    def points(self, n):
        xi = np.sqrt(n) * np.vstack([np.eye(n), -np.eye(n)])
        w = np.full(2 * n, 0.5 / n)
        return xi, w, w
