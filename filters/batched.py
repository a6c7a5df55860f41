"""Batched Monte Carlo: M runs of one filter on one model as a single array computation.

:func:`run_batched` takes the measurements of M runs ``Z`` (M, n, nz), their
priors ``X0`` (M, nx), ``P0`` (M, nx, nx) and one generator per run, and returns
the same list of :class:`~replay.filters.base.Estimates` as M calls of
``Filter.run`` — the same equations, the same random draws from the same
generators — but with the means stacked as (M, nx) and the covariances as
(M, nx, nx), so numpy does the loop over runs.

* Kalman family (``kf``, ``ekf``, ``ukf``, ``ckf``): fully batched. The EKF
  calls ``model.F``/``model.H`` once per run (those take a single state in the
  model protocol); ``f``, ``h`` and every matrix product, Cholesky factor and
  solve act on the whole stack. The equations are those of
  :mod:`replay.filters.kalman` and :mod:`replay.filters.sigma`.
* Bootstrap PF: particles (M, N, nx); ``model.f`` runs once on all of them;
  every random draw (prior, process noise, resampling) comes from the run's own
  generator in the same order as ``ParticleFilter.run``, and the weight and
  estimate arithmetic uses the same per-run functions, so the numbers are
  bit-for-bit those of the one-by-one runs.

Agreement with one-by-one runs. The Kalman family uses numpy's stacked LAPACK
(``np.linalg.cholesky``, ``np.linalg.solve``, LU) where the single-run code
calls LAPACK ``dpotrf``/``dposv`` directly, and stacked ``matmul`` instead of
BLAS ``gemv``: each step agrees to the last few bits (relative 1e-16), and the
difference stays at the rounding level along a run (the tests assert 1e-10
relative over 100 steps of the nonlinear sonar problem; about 1e-13 is typical).
The PF agrees exactly.

Extra output: the Kalman family records the normalised innovation squared
``info["nis"]`` (n,) = y' S^-1 y and its degrees of freedom ``info["nis_dof"]``
(number of measured components; 0 when the step had no measurement, NaN then).

Divergence is detected per run as in ``Filter.run`` (a Cholesky failure, a
non-finite or negative-variance covariance); a diverged run leaves the stack
and the others go on. ``step_seconds`` is the batch's step time divided by the
number of active runs (the amortised cost of one run's step).

Runs may be batched only when they share one model object's equations: pass
one ``model`` (the caller checks that the runs' models are equal).
"""
from __future__ import annotations

from time import perf_counter

import numpy as np

from replay.util.angles import residual, weighted_mean, wrap_components
from replay.util.linalg import cholesky
from replay.model import Model, is_diagonal, remap_indices

from .base import Estimates
from .kalman import EKF, KalmanFilter
from .pf import ParticleFilter
from .resampling import SCHEMES, effective_sample_size
from .sigma import CKF, UKF


def supports(flt) -> bool:
    """True when ``flt`` (exactly one of the built-in classes, or a filter with an
    ``engine(model, rngs)`` method) has a batched implementation."""
    return type(flt) in KINDS or hasattr(flt, "engine")


def exact(flt) -> bool:
    """True when the batched runs of ``flt`` give exactly the numbers of one-by-one runs."""
    if getattr(flt, "roughening", 0):  # the batched PF has no roughening: run one by one
        return False
    return supports(flt) and (getattr(KINDS.get(type(flt)), "exact", False) or hasattr(flt, "engine"))


def run_batched(flt, model, Z, X0, P0, rngs) -> list[Estimates]:
    """Run ``flt`` on M runs at once; returns one Estimates per run (see the module docstring)."""
    Z = np.asarray(Z, float)
    X0 = np.asarray(X0, float)
    P0 = np.asarray(P0, float)
    M, n = Z.shape[:2]
    if X0.shape != (M, model.nx) or P0.shape != (M, model.nx, model.nx) or len(rngs) != M:
        raise ValueError("run_batched: Z, X0, P0 and rngs must describe the same number of runs")
    engine = KINDS[type(flt)](flt, model, rngs) if type(flt) in KINDS else flt.engine(model, rngs)
    engine.start(X0, P0)
    X = np.full((M, n, model.nx), np.nan)
    P = np.full((M, n, model.nx, model.nx), np.nan)
    secs = np.full((M, n), np.nan)
    nis = np.full((M, n), np.nan)
    dof = np.zeros((M, n), int)
    diverged = [None] * M
    finite = np.isfinite(Z)
    active = np.arange(M)
    for k in range(n):
        if not len(active):
            break
        t0 = perf_counter()
        try:
            xk, Pk, nk, dk = engine.step(active, k, Z[active, k], finite[active, k])
        except np.linalg.LinAlgError:
            # find the runs that fail by stepping each alone (the Kalman steps are pure functions)
            xk, Pk = np.full((len(active), model.nx), np.nan), np.full((len(active), model.nx, model.nx), np.nan)
            nk, dk = np.full(len(active), np.nan), np.zeros(len(active), int)
            for j, m in enumerate(active):
                try:
                    a, b, c, d = engine.step(active[j:j + 1], k, Z[m:m + 1, k], finite[m:m + 1, k])
                    xk[j], Pk[j], nk[j], dk[j] = a[0], b[0], c[0], d[0]
                except np.linalg.LinAlgError:
                    pass  # left NaN: counted as diverged below
        dt = (perf_counter() - t0) / len(active)
        ok = np.isfinite(xk.sum(axis=1) + Pk.sum(axis=(1, 2))) & (np.diagonal(Pk, axis1=1, axis2=2).min(axis=1) >= 0)
        good = active[ok]
        X[good, k], P[good, k], secs[good, k] = xk[ok], Pk[ok], dt
        nis[good, k], dof[good, k] = nk[ok], dk[ok]
        for m in active[~ok]:
            diverged[m] = k
        if not ok.all():
            active = good
            engine.keep(ok)
    out = []
    for m in range(M):
        info = {"nis": nis[m], "nis_dof": dof[m]}
        engine.finish(m, info)
        out.append(Estimates(X[m], P[m], secs[m], diverged[m], info))
    return out


def _groups(finite):
    """Index groups of runs sharing one measurement pattern: (rows, mask or None for full, skip)."""
    full = finite.all(axis=1)
    if full.all():
        return [(slice(None), None)]
    patterns, inverse = np.unique(finite, axis=0, return_inverse=True)
    out = []
    for g, pat in enumerate(patterns):
        if pat.any():
            rows = np.flatnonzero(inverse.ravel() == g)
            out.append((rows, None if pat.all() else pat))
    return out


def _solve(S, B):
    """S^-1 B for stacked symmetric positive-definite S (Cholesky first: fails like dposv)."""
    np.linalg.cholesky(S)
    return np.linalg.solve(S, B)


def _T(A):
    return np.swapaxes(A, -1, -2)


class _Kalman:
    """Shared start/keep/step of the batched Kalman family; subclasses predict and update."""

    def __init__(self, flt, model, rngs):
        self.flt, self.model = flt, model

    def start(self, X0, P0):
        self.x, self.P = X0.copy(), P0.copy()
        self.ids = np.arange(len(X0))

    def keep(self, ok):
        self.x, self.P, self.ids = self.x[ok], self.P[ok], self.ids[ok]

    def finish(self, m, info):
        pass

    def step(self, rows, k, z, finite):
        """Predict and update the runs ``rows`` (run ids: all active runs, or one alone on a retry)."""
        pos = slice(None) if len(rows) == len(self.ids) else np.searchsorted(self.ids, rows)
        x, P = self.x[pos], self.P[pos]
        x, P = self.predict(x, P, k)
        nis, dof = np.full(len(x), np.nan), np.zeros(len(x), int)
        for g, mask in _groups(finite):
            xg, Pg, zg = x[g], P[g], z[g]
            if mask is not None:
                zg = zg[:, mask]
            xg, Pg, ng = self.update(xg, Pg, zg, k, mask)
            x[g], P[g], nis[g] = xg, Pg, ng
            dof[g] = zg.shape[1]
        self.x[pos], self.P[pos] = x, P
        return x.copy(), P.copy(), nis, dof

    def measurement(self, k, mask):
        m = self.model
        R, angles = m.measurement_cov(k), m.z_angles
        if mask is not None:
            R, angles = R[np.ix_(mask, mask)], remap_indices(angles, mask)
        return R, angles

    def correct(self, x, P, y, S, Pxz):
        """Shared tail of the sigma-point update: K = Pxz S^-1, x += K y, P -= K S K'."""
        K = _T(_solve(S, _T(Pxz)))
        x = wrap_components(x + (K @ y[..., None])[..., 0], self.model.x_angles)
        P = P - K @ S @ _T(K)
        return x, 0.5 * (P + _T(P))


def _nis(S, y):
    return np.einsum("mi,mi->m", y, np.linalg.solve(S, y[..., None])[..., 0])


class _BatchedEKF(_Kalman):
    """EKF/KF of :mod:`replay.filters.kalman` on a stack of runs (Joseph-form update)."""

    def predict(self, x, P, k):
        m = self.model
        F = np.stack([m.F(xi, k) for xi in x])
        x = wrap_components(m.f(x, k), m.x_angles)
        return x, F @ P @ _T(F) + m.process_cov(k)

    def update(self, x, P, z, k, mask):
        m = self.model
        H = np.stack([m.H(xi, k) for xi in x])
        zh = m.h(x, k)
        R, angles = self.measurement(k, mask)
        if mask is not None:
            H, zh = H[:, mask], zh[:, mask]
        y = residual(z, zh, angles)
        PHt = P @ _T(H)
        S = H @ PHt + R
        K = _T(_solve(S, _T(PHt)))
        x = wrap_components(x + (K @ y[..., None])[..., 0], m.x_angles)
        I_KH = np.eye(x.shape[1]) - K @ H
        P = I_KH @ P @ _T(I_KH) + K @ R @ _T(K)
        return x, 0.5 * (P + _T(P)), _nis(S, y)


class _BatchedSigma(_Kalman):
    """UKF/CKF of :mod:`replay.filters.sigma` on a stack of runs."""

    def __init__(self, flt, model, rngs):
        super().__init__(flt, model, rngs)
        self.xi, self.wm, self.wc = flt.points(model.nx)

    def sigma(self, x, P):
        return x[:, None, :] + self.xi @ _T(np.linalg.cholesky(P))

    def predict(self, x, P, k):
        m = self.model
        Y = m.f(self.sigma(x, P), k)
        x = weighted_mean(Y, self.wm, m.x_angles)
        D = residual(Y, x[:, None, :], m.x_angles)
        return x, (_T(D) * self.wc) @ D + m.process_cov(k)

    def update(self, x, P, z, k, mask):
        m = self.model
        X = self.sigma(x, P)
        Z = m.h(X, k)
        R, angles = self.measurement(k, mask)
        if mask is not None:
            Z = Z[..., mask]
        zh = weighted_mean(Z, self.wm, angles)
        Dz = residual(Z, zh[:, None, :], angles)
        Dx = residual(X, x[:, None, :], m.x_angles)
        S = (_T(Dz) * self.wc) @ Dz + R
        Pxz = (_T(Dx) * self.wc) @ Dz
        y = residual(z, zh, angles)
        x, P = self.correct(x, P, y, S, Pxz)
        return x, P, _nis(S, y)


class _BatchedPF:
    """Bootstrap PF of :mod:`replay.filters.pf` on a stack of runs (particles (M, N, nx))."""

    exact = True  # bit for bit the numbers of one-by-one runs

    def __init__(self, flt, model, rngs):
        self.flt, self.model, self.rngs = flt, model, list(rngs)
        self.resample = SCHEMES[flt.resampling]
        self.vector_noise = type(model).sample_f is Model.sample_f

    def start(self, X0, P0):
        N, M = self.flt.n_particles, len(X0)
        self.ids = np.arange(M)
        self.particles = np.empty((M, N, X0.shape[1]))
        for m in range(M):
            L = np.linalg.cholesky(P0[m])
            self.particles[m] = X0[m] + self.rngs[m].standard_normal((N, X0.shape[1])) @ L.T
        self.logw = np.full((M, N), -np.log(N))
        self.w = np.full((M, N), 1.0 / N)
        self.resampled = np.zeros(M, int)

    def keep(self, ok):
        self.ids = self.ids[ok]
        self.particles, self.logw, self.w = self.particles[ok], self.logw[ok], self.w[ok]

    def finish(self, m, info):
        info["resampled"] = int(self.resampled[m])
        info.pop("nis"), info.pop("nis_dof")

    def step(self, rows, k, z, finite):
        if len(rows) != len(self.ids):  # a lone retry after a failure: not reached by the PF steps
            raise np.linalg.LinAlgError("particle filter step failed")
        model = self.model
        self._propagate(k)
        full, some = finite.all(axis=1), finite.any(axis=1)
        for j in np.flatnonzero(some):
            mask = None if full[j] else finite[j]
            ll = model.loglik(z[j], self.particles[j], k, mask)
            logw = self.logw[j] + ll
            logw -= logw.max()
            w = np.exp(logw)
            s = w.sum()
            self.w[j] = w / s
            self.logw[j] = logw - np.log(s)
        M, N = self.w.shape
        x = np.empty((M, model.nx))
        P = np.empty((M, model.nx, model.nx))
        for j in range(M):
            w, parts = self.w[j], self.particles[j]
            x[j] = weighted_mean(parts, w, model.x_angles)
            D = residual(parts, x[j], model.x_angles)
            P[j] = (D.T * w) @ D
            if effective_sample_size(w) < self.flt.ess_threshold * N:
                self.particles[j] = parts[self.resample(w, self.rngs[self.ids[j]])]
                self.w[j] = 1.0 / N
                self.logw[j] = -np.log(N)
                self.resampled[self.ids[j]] += 1
        return x, P, np.full(M, np.nan), np.zeros(M, int)

    def _propagate(self, k):
        model = self.model
        if not self.vector_noise:
            for j, m in enumerate(self.ids):
                self.particles[j] = model.sample_f(self.particles[j], k, self.rngs[m])
            return
        y = model.f(self.particles, k)
        Q = model.process_cov(k)
        diag = is_diagonal(Q)
        scale = np.sqrt(np.diagonal(Q)) if diag else cholesky(Q).T
        for j, m in enumerate(self.ids):
            e = self.rngs[m].standard_normal(y.shape[1:])
            y[j] = y[j] + (e * scale if diag else e @ scale)
        self.particles = y


KINDS = {EKF: _BatchedEKF, KalmanFilter: _BatchedEKF, UKF: _BatchedSigma, CKF: _BatchedSigma,
         ParticleFilter: _BatchedPF}
