"""Sigma-point Kalman filters: the unscented (UKF) and cubature (CKF) filters, over the run axis.

Both approximate the Gaussian integrals of the Kalman recursion by a weighted
set of points ``X_i = x + L xi_i`` (``L`` the lower Cholesky factor of ``P``),
pushed through ``f`` and ``h`` as one array. For each step and run:

    predict   Y_i = f(X_i),  x- = sum wm_i Y_i,  P- = sum wc_i (Y_i - x-)(Y_i - x-)' + Q
    update    X_i from (x-, P-),  Z_i = h(X_i),  z^ = sum wm_i Z_i
              Pzz = sum wc_i (Z_i - z^)(Z_i - z^)',  Pxz = sum wc_i (X_i - x-)(Z_i - z^)'
              S = Pzz + R,  K = Pxz S^-1,  x = x- + K (z - z^),  P = P- - K S K' = P- - K Pxz'
    NIS       y' S^-1 y,  y = z - z^

Means of angle components are circular means and every deviation of an angle
component (``Y_i - x-``, ``Z_i - z^``, ``z - z^``) is wrapped to [-pi, pi);
``X_i - x-`` is ``L xi_i`` exactly. Averaging raw angles instead makes a point
cloud that straddles +-pi average to about 0 — the reason a popular library's
CKF diverges on the sonar-tracking scenario of paper 002 (azimuth crossing pi).

The points are regenerated from (x-, P-) before the update, as in the CKF of
Arasaratnam & Haykin (2009) and the UKF of Wan & van der Merwe (2000) with
augmentation-free additive noise.

The step is written once, over any leading axes: a stack of runs ``x`` (M,
nx), ``P`` (M, nx, nx), points (M, m, nx), or one run without the run axis
(functions :func:`sigma_points`, :func:`predict`, :func:`innovation`,
:func:`correct`; see :mod:`replay.filters.kalman` for why a slice of a stack
gets the numbers of one run bit for bit). The engine runs them on the active
runs; the per-run State API of :class:`SigmaPointFilter` (``predict``,
``update``, ``innovation``, ``correct``, ``_sigma``; used by the subclasses
written per run, the AUKF of paper 001 and the STCKF of paper 002) calls the
same functions on one run.
"""
from __future__ import annotations

import numpy as np

from replay.util import kernels
from replay.util.angles import angle_mask, residual, weighted_mean
from replay.util.errors import ReplayError
from replay.util.params import Param

from .base import PER_RUN, Filter, on_points
from .kalman import KalmanEngine, measurement, not_pd, stack_of


# --- the step over a stack of runs -------------------------------------------------------
def sigma_points(x, P, xi):
    """Points X_i = x + L xi_i (..., m, nx) and their deviations L xi_i from x (compiled:
    :func:`replay.util.kernels.sigma_points`). LinAlgError when a P is not positive definite."""
    one = x.ndim == 1
    x2, P3 = stack_of(x, one), stack_of(P, one)
    X, dev = np.empty((len(x2),) + xi.shape), np.empty((len(x2),) + xi.shape)
    bad = kernels.sigma_points(x2, P3, xi, X, dev)
    if bad >= 0:
        raise np.linalg.LinAlgError(f"covariance not positive definite (run {bad} of the stack)")
    return (X[0], dev[0]) if one else (X, dev)


def predict(model, x, P, k, xi, wm, wc):
    """Predicted means (..., nx) and covariances (..., nx, nx) (the module docstring's predict)."""
    Y = on_points(model.f, sigma_points(x, P, xi)[0], k)
    x = weighted_mean(Y, wm, model.x_angles)
    D = residual(Y, x[..., None, :], model.x_angles)
    return x, (D.swapaxes(-1, -2) * wc) @ D + model.process_cov(k)


def innovation(model, x, P, z, k, mask, xi, wm, wc):
    """Innovations y (..., nzm), Pzz (..., nzm, nzm), Pxz (..., nx, nzm) and R (nzm, nzm).

    ``z`` (..., nzm) holds the measured components ``mask`` (None: all) of each run.
    """
    X, dev = sigma_points(x, P, xi)
    Z = on_points(model.h, X, k)
    R, angles = measurement(model, k, mask)
    if mask is not None:
        Z = Z[..., mask]
    zh = weighted_mean(Z, wm, angles)
    Dz = residual(Z, zh[..., None, :], angles)
    W = wc[:, None] * Dz
    return residual(z, zh, angles), Dz.swapaxes(-1, -2) @ W, dev.swapaxes(-1, -2) @ W, R


def correct(x, P, y, S, Pxz, x_angles=()):
    """x + K y (state angles wrapped), P - K Pxz' (symmetrised) and the NIS, K = Pxz S^-1: the
    compiled :func:`replay.util.kernels.kalman_correct` on each run (new arrays returned).
    LinAlgError when an S is not positive definite."""
    one = x.ndim == 1
    x3, P3 = np.array(x[None] if one else x, dtype=float), np.array(P[None] if one else P, dtype=float)
    nis = np.empty(len(x3))
    bad = kernels.kalman_correct(x3, P3, stack_of(y, one), stack_of(S, one), stack_of(Pxz, one),
                                 angle_mask(x_angles, x3.shape[-1]), nis)
    if bad >= 0:
        raise not_pd(bad)
    return (x3[0], P3[0], nis[0]) if one else (x3, P3, nis)


class SigmaEngine(KalmanEngine):
    """M runs of a UKF or CKF."""

    def __init__(self, flt, model, rngs):
        super().__init__(flt, model, rngs)
        self.pts = flt.points(model.nx)

    def predict(self, x, P, k):
        return predict(self.model, x, P, k, *self.pts)

    def update(self, x, P, z, k, mask):
        y, Pzz, Pxz, R = innovation(self.model, x, P, z, k, mask, *self.pts)
        return correct(x, P, y, Pzz + R, Pxz, self.model.x_angles)


# --- the filters -------------------------------------------------------------------------
class SigmaPointFilter(Filter):
    """Shared engine and per-run API; subclasses set the unit points ``xi`` (m, n) and weights."""

    PER_RUN_API = PER_RUN + ("innovation", "correct", "_sigma")

    def points(self, n: int):
        """Unit points (m, n), mean weights (m,), covariance weights (m,)."""
        raise NotImplementedError

    def engine(self, model, rngs):
        if self.overrides(SigmaPointFilter, self.PER_RUN_API):  # a subclass written per run
            return super().engine(model, rngs)
        return SigmaEngine(self, model, rngs)

    # --- per-run State API: the functions above on one run (no run axis) ---------------
    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        state.xi, state.wm, state.wc = self.points(state.model.nx)

    def _sigma(self, state, x, P):
        """Points x + L xi_i (m, nx); their deviations L xi_i are kept in ``state.dev``."""
        X, state.dev = sigma_points(x, P, state.xi)
        return X

    def predict(self, state, k):
        state.x, state.P = predict(state.model, state.x, state.P, k, state.xi, state.wm, state.wc)

    def innovation(self, state, z, k, mask):
        """Innovation y, Pzz and Pxz (without R), and R, of the measured components ``mask``."""
        z = z if mask is None else z[mask]
        return innovation(state.model, state.x, state.P, z, k, mask, state.xi, state.wm, state.wc)

    def update(self, state, z, k, mask):
        y, Pzz, Pxz, R = self.innovation(state, z, k, mask)
        self.correct(state, y, Pzz + R, Pxz)

    def correct(self, state, y, S, Pxz):
        state.x, state.P, state.nis = correct(state.x, state.P, y, S, Pxz, state.model.x_angles)


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
    PARAMS = (
        Param("alpha", float, 0.5, "spread of the sigma points about the mean (van der Merwe eq. 3.11)",
              low=0.0, high=1.0, low_open=True),
        Param("beta", float, 2.0, "prior knowledge of the distribution (2: optimal for a Gaussian)", low=0.0),
        Param("kappa", float, 0.0, "secondary scaling; n + kappa must be positive for the state dimension n"),
    )

    def points(self, n):
        if not n + self.kappa > 0:
            raise ReplayError(f"{self.owner()}: kappa must be > -{n} for a state of dimension {n} "
                              f"(got {self.kappa:g})")
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
    PARAMS = ()

    def points(self, n):
        xi = np.sqrt(n) * np.vstack([np.eye(n), -np.eye(n)])
        w = np.full(2 * n, 0.5 / n)
        return xi, w, w
