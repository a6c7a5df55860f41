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

from functools import lru_cache

import numpy as np

from replay.filters.case import Case
from replay.util.angles import angle_mask, wrap_components
from replay.util.errors import ReplayError
from replay.util.params import Param

from .base import PER_RUN, Filter, on_points
from . import kalman, kalman_loops
from . import kalman_kernels as kernels
from .kalman import KalmanEngine, measurement, not_pd, stack_of


# --- the step over a stack of runs -------------------------------------------------------
def sigma_points(x, P, xi):
    """Points X_i = x + L xi_i (..., m, nx) and their deviations L xi_i from x (compiled:
    :func:`replay.filters.kalman_kernels.sigma_points`). LinAlgError when a P is not positive definite."""
    one = x.ndim == 1
    x2, P3 = stack_of(x, one), stack_of(P, one)
    X, dev = np.empty((len(x2),) + xi.shape), np.empty((len(x2),) + xi.shape)
    bad = kernels.sigma_points(x2, P3, xi, X, dev)
    if bad >= 0:
        raise np.linalg.LinAlgError(f"covariance not positive definite (run {bad} of the stack)")
    return (X[0], dev[0]) if one else (X, dev)


def predict(model, x, P, k, xi, wm, wc):
    """Predicted means (..., nx) and covariances (..., nx, nx) (the module docstring's predict;
    the moments compiled: :func:`replay.filters.kalman_kernels.sigma_moments`)."""
    one = x.ndim == 1
    Y = on_points(model.f, sigma_points(x, P, xi)[0], k)
    Y3 = stack_of(Y, one)
    xm, Pm = mean_at_f(model, x, k, one, Y3.shape), np.empty((len(Y3),) + (Y3.shape[2],) * 2)
    kernels.sigma_moments(
        Y3,
        wm,
        wc,
        angle_mask(model.x_angles, Y3.shape[2]),
        np.ascontiguousarray(model.process_cov(k), dtype=float),
        xm,
        Pm,
        model.mean_at_f,
    )
    return (xm[0], Pm[0]) if one else (xm, Pm)


def mean_at_f(model, x, k, one, shape):
    """The predicted means' array (M, nx): f(x) with its angles wrapped when the model's mean is
    f(mean) (:attr:`replay.model.Model.mean_at_f`; the moments keep it), else unset."""
    if not model.mean_at_f:
        return np.empty(shape[::2])
    return stack_of(wrap_components(model.f(x, k), model.x_angles), one).copy()


def innovation(model, x, P, z, k, mask, xi, wm, wc):
    """Innovations y (..., nzm), Pzz (..., nzm, nzm), Pxz (..., nx, nzm) and R (nzm, nzm).

    ``z`` (..., nzm) holds the measured components ``mask`` (None: all) of each run (the
    moments compiled: :func:`replay.filters.kalman_kernels.innovation_moments`).
    """
    one = x.ndim == 1
    X, dev = sigma_points(x, P, xi)
    Z = on_points(model.h, X, k)
    R, angles = measurement(model, k, mask)
    if mask is not None:
        Z = Z[..., mask]
    Z3, D3, z2 = stack_of(Z, one), stack_of(dev, one), stack_of(z, one)
    M, nz, nx = len(Z3), Z3.shape[2], D3.shape[2]
    y, Pzz, Pxz = np.empty((M, nz)), np.empty((M, nz, nz)), np.empty((M, nx, nz))
    kernels.innovation_moments(Z3, D3, z2, wm, wc, angle_mask(angles, nz), y, Pzz, Pxz)
    return (y[0], Pzz[0], Pxz[0], R) if one else (y, Pzz, Pxz, R)


def correct(x, P, y, S, Pxz, x_angles=()):
    """x + K y (state angles wrapped), P - K Pxz' (symmetrised) and the NIS, K = Pxz S^-1: the
    compiled :func:`replay.filters.kalman_kernels.kalman_correct` on each run (new arrays returned).
    LinAlgError when an S is not positive definite."""
    one = x.ndim == 1
    x3, P3 = np.array(x[None] if one else x, dtype=float), np.array(P[None] if one else P, dtype=float)
    nis = np.empty(len(x3))
    bad = kernels.kalman_correct(
        x3, P3, stack_of(y, one), stack_of(S, one), stack_of(Pxz, one), angle_mask(x_angles, x3.shape[-1]), nis
    )
    if bad >= 0:
        raise not_pd(bad)
    return (x3[0], P3[0], nis[0]) if one else (x3, P3, nis)


class SigmaEngine(KalmanEngine):
    """M runs of a UKF or CKF: the functions above fused into compiled calls, the same kernels
    in the same order (so the same numbers as :func:`predict`, :func:`innovation` and
    :func:`correct`). The engine keeps the points ``X`` (and their deviations ``dev``) of its
    current means and covariances: made by :func:`replay.filters.kalman_kernels.sigma_predict` with the
    predicted moments and by :func:`replay.filters.kalman_kernels.sigma_update` with the corrected ones,
    so each step is f, one compiled call, h, one compiled call. A covariance without a
    Cholesky factor raises LinAlgError where the points are used, as :func:`sigma_points` does."""

    def __init__(self, flt, model, rngs):
        super().__init__(flt, model, rngs)
        self.rule = kernels.Rule(*flt.points(model.nx))  # xi, wm, wc
        self.xmask = angle_mask(model.x_angles, model.nx)

    def start(self, X0, P0):
        super().start(X0, P0)
        shape = (len(X0),) + self.rule.xi.shape
        self.X, self.dev = np.empty(shape), np.empty(shape)
        self.missing = np.zeros(len(X0), bool)  # runs without points (no Cholesky factor)
        self.unmade(kernels.sigma_points(stack_of(X0, False), stack_of(P0, False), self.rule.xi, self.X, self.dev))

    def unmade(self, bad, rows=None):
        """Mark the runs from ``bad`` on (of ``rows``, or of all) as without points."""
        if bad >= 0:
            self.missing[slice(bad, None) if rows is None else rows[bad:]] = True
        self.all_made = bad < 0 and (rows is None or self.all_made)

    def keep(self, ok):
        super().keep(ok)
        self.X, self.dev, self.missing = self.X[ok], self.dev[ok], self.missing[ok]
        self.all_made = not self.missing.any()

    def run_all(self, Z, finite):
        return kalman.run_kernels(
            self,
            Z,
            finite,
            (0, 1),
            kalman_loops.sigma_run,
            kalman_loops.SIGMA_RUN,
            self.rule,
            bool(self.model.mean_at_f),
        )

    def points(self, rows):
        """The points and deviations of the runs ``rows`` (None: all)."""
        missing = self.missing if rows is None else self.missing[rows]
        if not self.all_made and missing.any():
            raise np.linalg.LinAlgError(
                f"covariance not positive definite (run {int(np.argmax(missing))} of the stack)"
            )
        return (self.X, self.dev) if rows is None else (self.X[rows], self.dev[rows])

    def predict(self, x, P, k):
        one, m = x.ndim == 1, self.model
        Y = on_points(m.f, self.points(None)[0], k)
        M, p, nx = Y.shape
        xm, Pm = mean_at_f(m, x, k, one, Y.shape), np.empty((M, nx, nx))
        self.X, self.dev = np.empty(Y.shape), np.empty(Y.shape)
        self.missing = np.zeros(M, bool)
        self.unmade(
            kernels.sigma_predict(
                Y,
                self.rule,
                self.xmask,
                np.ascontiguousarray(m.process_cov(k), dtype=float),
                xm,
                Pm,
                kernels.Points(self.X, self.dev),
                m.mean_at_f,
            )
        )
        return (xm[0], Pm[0]) if one else (xm, Pm)

    def update(self, x, P, z, k, mask, rows=None):
        """In place on x, P (the fresh arrays of :meth:`predict`, or copies of their rows)."""
        one, m = x.ndim == 1, self.model
        X, dev = self.points(rows)
        Z = on_points(m.h, X, k)
        R, angles = measurement(m, k, mask)
        if mask is not None:
            Z = np.ascontiguousarray(Z[..., mask])
        x3, P3 = (x[None], P[None]) if one else (x, P)
        nis = np.empty(len(x3))
        Xn, devn = (self.X, self.dev) if rows is None else (np.empty(X.shape), np.empty(X.shape))
        meas = kernels.Meas(Z, stack_of(z, one), np.ascontiguousarray(R, dtype=float), angle_mask(angles, Z.shape[2]))
        args = (meas, dev, self.rule, x3, P3, self.xmask, nis, kernels.Points(Xn, devn))
        if not self.gated:
            bad = kernels.sigma_update(*args)
        else:
            gate, done = self.gate(mask, rows, len(x3))
            bad = kernels.sigma_update_gated(*args, gate)
            self.cut = done()
        if 0 <= bad < len(x3):
            raise not_pd(bad)
        if rows is not None:
            self.X[rows], self.dev[rows] = Xn, devn
        self.unmade(bad - len(x3), rows)
        return (x, P, nis[0]) if one else (x, P, nis)


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
    CASE = Case(params={"alpha": 0.8})
    PARAMS = (
        Param(
            "alpha",
            float,
            0.5,
            "spread of the sigma points about the mean (van der Merwe eq. 3.11)",
            low=0.0,
            high=1.0,
            low_open=True,
        ),
        Param("beta", float, 2.0, "prior knowledge of the distribution (2: optimal for a Gaussian)", low=0.0),
        Param("kappa", float, 0.0, "secondary scaling; n + kappa must be positive for the state dimension n"),
    )

    def points(self, n):
        if not n + self.kappa > 0:
            raise ReplayError(f"{self.owner()}: kappa must be > -{n} for a state of dimension {n} (got {self.kappa:g})")
        return tuple(a.copy() for a in _unscented(n, float(self.alpha), float(self.beta), float(self.kappa)))


class CKF(SigmaPointFilter):
    """Cubature Kalman filter, third-degree spherical-radial rule (Arasaratnam & Haykin 2009).

    2n points xi_i = sqrt(n) [+-e_i], equal weights 1 / (2n).
    """

    name = "ckf"
    PARAMS = ()

    def points(self, n):
        xi, w = (a.copy() for a in _cubature(n))
        return xi, w, w


@lru_cache(maxsize=32)
def _unscented(n, alpha, beta, kappa):
    """The unscented points and weights of :class:`UKF` (kept per dimension and parameters: the
    engine of every run asks for them; callers get copies)."""
    lam = alpha**2 * (n + kappa) - n
    c = np.sqrt(n + lam)
    xi = np.vstack([np.zeros(n), c * np.eye(n), -c * np.eye(n)])
    wm = np.full(2 * n + 1, 0.5 / (n + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = wm[0] + 1 - alpha**2 + beta
    return xi, wm, wc


@lru_cache(maxsize=32)
def _cubature(n):
    """The cubature points and their (equal) weights of :class:`CKF` (kept per dimension)."""
    return np.sqrt(n) * np.vstack([np.eye(n), -np.eye(n)]), np.full(2 * n, 0.5 / n)
