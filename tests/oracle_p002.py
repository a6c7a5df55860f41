"""The readable numpy reference of paper 002's particle-level work, kept only to check the compiled kernels.

The library computes the per-particle cubature step, the importance draw and
weight, and the GWO/IGWO move only in numba (:mod:`replay.filters.p002.compiled`).
This module is the former numpy engine, kept under ``tests/`` as a test oracle
(issue 11: "a numpy engine kept only as a test oracle"): the same equations
written as stacked array operations, which ``tests/test_compiled.py`` runs
beside the kernels from the same generators and compares step by step.

* :class:`CubatureOracle` — for M runs x N particles, each particle's CKF /
  STCKF step (002 §2.2), the draw x ~ N(m, P) and the weight
  w ∝ w_prev p(z | x) p(x | x_prev) / q(x) (002 §2.1); a predict-only step
  draws from the prediction;
* :func:`gwo_optimize` — t_max GWO / IGWO iterations (002 §3.1–3.2) with
  :func:`entropy_weights` and elitism;
* :func:`pso_optimize` — the numpy PSO that :func:`replay.filters.p002.pso.optimize` was
  before its array passes were compiled (same operations, same order: equal bit for bit);
* :func:`oracle_filter` — a registered filter (stcpf, igwo-stcpf, gwo-pf, ...)
  whose engine runs this numpy code instead of the kernels.

Arithmetic shortcuts (exact in real arithmetic): with cubature points
X_c = m ± sqrt(n) L e_c, P_xz = sqrt(n)/(2n) L (Z_+ - Z_-)'; the posterior is
P = P- - P_xz K'; the importance density's exponent at x = m + L e is e'e.
"""
from __future__ import annotations

import numpy as np

from replay.filters import make_filter
from replay.filters import particles
from replay.filters.p002 import gwo, pso
from replay.filters.p002.igwo_stcpf import SwarmEngine, residual_fitness
from replay.filters.p002.stack import fast_residual
from replay.filters.p002.stcpf import Engine, propagate
from replay.model import is_diagonal
from replay.util.angles import index, residual, wrap_components


# --- the numpy STCKF fading factor (stacks of runs and particles): the kernel's independent check ---
def next_V(V, e, rho):
    """V_{k+1} = (rho V_k + e e') / (1 + rho); V_1 = e e' when ``V`` is None (batched over leading axes)."""
    ee = e[..., :, None] * e[..., None, :]
    return ee if V is None else (rho * V + ee) / (1.0 + rho)


def fading_factor(V, H, F, P_prev, Q, R, beta, m_form="propagated"):
    """lambda = max(1, tr(N) / tr(M)) (1 where tr(M) <= 0); works on stacks of matrices.

    Only traces are needed: tr(N) = tr(V) - tr(H Q H') - beta tr(R) and
    tr(H F P F' H') = sum((H F P) * (H F)), so no product is formed beyond H F P.
    """
    HF = H @ F
    trN = np.trace(V, axis1=-2, axis2=-1) - ((H @ Q) * H).sum(axis=(-2, -1)) - beta * np.trace(R)
    if m_form == "propagated":
        trM = ((HF @ P_prev) * HF).sum(axis=(-2, -1))
    else:
        trM = np.trace(HF @ np.swapaxes(H, -1, -2), axis1=-2, axis2=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam0 = np.where(trM > 0, trN / np.where(trM > 0, trM, 1.0), 1.0)
    return np.maximum(1.0, lam0)


# --- stacked small-matrix helpers -------------------------------------------------------------
def batched_cholesky(P):
    """Lower Cholesky factors of a stack; a non-positive-definite matrix is repaired by flooring its
    eigenvalues at 1e-12 max(1, largest). Returns (L, repaired per leading index or None)."""
    try:
        return np.linalg.cholesky(P), None
    except np.linalg.LinAlgError:
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        s, U = np.linalg.eigh(P)
        floor = 1e-12 * np.maximum(1.0, s.max(axis=-1, keepdims=True))
        bad = s.min(axis=-1) <= floor[..., 0]
        P = (U * np.maximum(s, floor)[..., None, :]) @ np.swapaxes(U, -1, -2)
        return np.linalg.cholesky(P), bad


def circular_mean(Y, angles):
    """Equal-weight mean over the points axis -2 (circular for the ``angles`` components)."""
    mean = np.einsum("...ci->...i", Y) * (1.0 / Y.shape[-2])
    if angles:
        i = index(tuple(angles))
        a = Y[..., i]
        mean[..., i] = np.arctan2(np.einsum("...ci->...i", np.sin(a)), np.einsum("...ci->...i", np.cos(a)))
    return mean


def batched_jacobian(fun, X, k, out_angles=(), step=1e-6):
    """Central-difference Jacobians of ``fun`` at each row of ``X`` (..., n) -> (..., m, n), one call to ``fun``."""
    lead, n = X.shape[:-1], X.shape[-1]
    X = X.reshape(-1, n)
    N = len(X)
    eps = step * np.maximum(1.0, np.abs(X))
    E = eps[:, :, None] * np.eye(n)
    pts = np.concatenate([X[:, None, :] + E, X[:, None, :] - E], axis=1)
    Y = fun(pts, k)
    d = residual(Y[:, :n], Y[:, n:], out_angles)
    J = np.swapaxes(d / (2.0 * eps)[:, :, None], 1, 2)
    return J.reshape(lead + J.shape[1:])


# --- GWO / IGWO -------------------------------------------------------------------------------
def entropy_weights(f, eps=1e-12, xi=1e-4):
    """IGWO leader weights (002 §3.2.2): p_i = (1/(f_i+eps)) / sum_j 1/(f_j+eps), w_i = max(1 + p_i log(p_i+eps), xi),
    normalised along the last axis."""
    inv = 1.0 / (np.asarray(f, float) + eps)
    p = inv / inv.sum(axis=-1, keepdims=True)
    w = np.maximum(1.0 + p * np.log(p + eps), xi)
    return w / w.sum(axis=-1, keepdims=True)


def gwo_optimize(X, fitness, rng, t_max=20, improved=True, a_start=2.0, a_end=0.0, b_start=1.0, b_end=0.5,
                 xi=1e-4, eps=1e-12, form="centred", movable=None):
    """``t_max`` GWO (``improved=False``) or IGWO iterations on wolves X (N, d), or M swarms (M, N, d) with M
    generators. Per wolf and leader L (alpha, beta, delta: fitness order, ties by index), A = a (2 r1 - 1),
    C = 2 r2: X_L' = X_L - A |C X_L - X|; X <- sum_L w_L X_L' (w_L = 1/3, or the entropy weights);
    the leaders stay (elitism); ``movable`` (M, d) bool: only those components move.
    Returns wolves, fitness, best fitness before and after each iteration."""
    X, rngs, fitness, _, single = gwo.as_runs(X, rng, fitness, None)
    M, n, d = X.shape
    rows = np.arange(M)[:, None]
    f = fitness(X)
    best = np.empty((M, t_max + 1))
    best[:, 0] = f.min(axis=1)
    k = min(3, n)
    a = gwo.schedule(t_max, improved, a_start, a_end, b_start, b_end, form)
    r = gwo.draws(rngs, (t_max, 2, k, n, d))
    A = a[:, None, None, None] * (2.0 * r[:, :, 0] - 1.0)
    C = 2.0 * r[:, :, 1]
    w = np.full((M, k), 1.0 / k)
    for t in range(t_max):
        lead = np.argsort(f, axis=1, kind="stable")[:, :k]
        fl = f[rows, lead]
        if improved:
            w = entropy_weights(fl, eps, xi)
        XL = X[rows, lead][:, :, None, :]
        Y = XL - A[:, t] * np.abs(C[:, t] * XL - X[:, None])
        Xn = np.einsum("mk,mknd->mnd", w, Y)
        if movable is not None:
            Xn = np.where(np.asarray(movable)[:, None, :], Xn, X)
        Xn[rows, lead] = XL[:, :, 0]
        fn = fitness(Xn)
        fn[rows, lead] = fl
        X, f = Xn, fn
        best[:, t + 1] = f.min(axis=1)
    assert np.all(np.diff(best, axis=1) <= 0), "GWO elitism violated"
    return (X[0], f[0], best[0]) if single else (X, f, best)


def pso_optimize(X, fitness, rng, iterations=20, omega_max=0.9, omega_min=0.4, alpha=0.2, c1=(2.0, 1.0),
                 c2=(1.5, 2.0), project=None, movable=None):
    """PSO (002 §4.1) as numpy array operations: V = w V + c1 r1 (pbest - X) + c2 r2 (g - X), X = X + V,
    projected; the arguments and returns of :func:`replay.filters.p002.pso.optimize`."""
    X, rngs, fitness, project, single = gwo.as_runs(X, rng, fitness, project)
    M = len(X)
    keep = None if movable is None else np.asarray(movable, float).reshape(M, 1, -1)
    if project is not None:
        X = project(X)
    f = fitness(X)
    pbest, pf = X.copy(), f.copy()
    rows = np.arange(M)
    g = np.argmin(pf, axis=1)
    V = np.zeros_like(X)
    best = np.empty((M, iterations + 1))
    best[:, 0] = pf[rows, g]
    t = np.arange(1, iterations + 1)
    w = pso.inertia(t, omega_max, omega_min, alpha)
    a1, a2 = pso.ramp(t, iterations, *c1), pso.ramp(t, iterations, *c2)
    r = gwo.draws(rngs, (iterations, 2) + X.shape[1:])  # (M, iterations, 2, N, d)
    R1, R2 = r[:, :, 0], r[:, :, 1]
    R1 *= a1[:, None, None]
    R2 *= a2[:, None, None]
    for i in range(iterations):
        V *= w[i]
        t = pbest - X
        t *= R1[:, i]
        V += t
        np.subtract(pbest[rows, g][:, None, :], X, out=t)
        t *= R2[:, i]
        V += t
        if keep is not None:
            V *= keep
        X = X + V
        if project is not None:
            X = project(X)
        f = fitness(X)
        better = f < pf
        np.copyto(pbest, X, where=better[..., None])
        np.copyto(pf, f, where=better)
        g = np.argmin(pf, axis=1)
        best[:, i + 1] = pf[rows, g]
    return (X[0], f[0], best[0]) if single else (X, f, best)


# --- the numpy cubature engine ------------------------------------------------------------------
class CubatureOracle:
    """The numpy step of the STCPF / CPF engine (mixed in before :class:`replay.filters.p002.stcpf.Engine`)."""

    def step(self, k, Z, finite):
        pattern = finite[0]
        if not (finite == pattern).all():
            raise ValueError("runs with different missing-measurement patterns cannot share a batched step")
        self.predict(k)
        if pattern.any():
            self.update(Z, k, None if pattern.all() else pattern)
        x, P = self.estimate()
        M = len(x)
        return x, P, np.full(M, np.nan), np.zeros(M, int)

    def cholesky(self, P):
        L, bad = batched_cholesky(P)
        if bad is not None:
            self.repairs[self.ids] += bad.reshape(len(self.ids), -1).sum(axis=1)
        return L

    def points(self, X, P, L=None):
        L = self.cholesky(P) if L is None else L
        sL = np.sqrt(self.model.nx) * np.swapaxes(L, -1, -2)
        Xb = X[..., None, :]
        return np.concatenate([Xb + sL, Xb - sL], axis=-2), L

    def jacobian(self, analytic, fun, X, k, angles):
        """The model's own Jacobians when it declares ``vector_jacobians`` (stacks of states), else
        central differences."""
        if getattr(self.model, "vector_jacobians", False):
            return analytic(X, k)
        return batched_jacobian(fun, X, k, angles, self.model.jacobian_step)

    def predict(self, k):
        m = self.model
        self.Qk = m.process_cov(k)
        self.updated = False
        if self.prior:
            self.X = propagate(m, self.X, k, self.active_rngs())
            return
        self.fx = m.f(self.X, k)
        if getattr(self.flt, "prior_cov", "propagated") == "transition":  # N(f(x), Q) of the fixed sample
            self.P_prev = np.zeros_like(self.P)
            self.mean = wrap_components(self.fx, m.x_angles)
            self.Pm = np.broadcast_to(self.Qk, self.P.shape).copy()
        else:
            self.P_prev = self.P
            pts, _ = self.points(self.X, self.P, self.L)
            Y = m.f(pts, k)
            self.mean = circular_mean(Y, m.x_angles)
            D = fast_residual(Y, self.mean[..., None, :], m.x_angles)
            self.Pm = np.swapaxes(D, -1, -2) @ D / D.shape[-2] + self.Qk
        if self.flt.proposal == "stckf":
            self.F = self.jacobian(m.F, m.f, self.X, k, m.x_angles)

    def update(self, z, k, mask):
        meas = self.measurement(k, mask)
        zz = z if mask is None else z[:, mask]
        if self.prior:
            self.logw = self.logw + self.loglik(zz, self.X, k, mask, meas)
        else:
            mean, P = self.posterior(zz, k, mask, meas)
            self.draw(mean, P)
            self.logw = self.logw + self.loglik(zz, self.X, k, mask, meas) + self.log_ratio()
        self.updated = True
        self.relocate(zz, k, mask, meas)

    def posterior(self, zz, k, mask, meas):
        m = self.model
        R, zang = meas[0], meas[1]
        n = m.nx
        pts, L = self.points(self.mean, self.Pm)
        Z = m.h(pts, k)
        if mask is not None:
            Z = Z[..., mask]
        zh = circular_mean(Z, zang)
        Dz = fast_residual(Z, zh[..., None, :], zang)
        c = 2 * n
        Pzz = np.swapaxes(Dz, -1, -2) @ Dz / c
        Pxz = (np.sqrt(n) / c) * (L @ (Dz[..., :n, :] - Dz[..., n:, :]))
        Pm = self.Pm
        if self.flt.proposal == "stckf":
            lam = self.fading(zz, k, mask, R, zang)[..., None, None]
            Pzz, Pxz = lam * Pzz, lam * Pxz
            if self.flt.scale_prior:
                Pm = lam * Pm
        S = Pzz + R
        K = np.swapaxes(np.linalg.solve(S, np.swapaxes(Pxz, -1, -2)), -1, -2)
        y = fast_residual(zz[:, None, :], zh, zang)
        mean = wrap_components(self.mean + (K @ y[..., None])[..., 0], m.x_angles)
        P = Pm - Pxz @ np.swapaxes(K, -1, -2)
        return mean, 0.5 * (P + np.swapaxes(P, -1, -2))

    def fading(self, zz, k, mask, R, zang):
        m, flt = self.model, self.flt
        H = self.jacobian(m.H, m.h, self.mean, k, m.z_angles)
        zh = m.h(self.mean, k)
        if mask is not None:
            H, zh = H[..., mask, :], zh[..., mask]
        key = None if mask is None else tuple(mask)
        if key != self.V_key:
            self.V, self.V_key = None, key
        self.V = next_V(self.V, fast_residual(zz[:, None, :], zh, zang), flt.rho)
        lam = fading_factor(self.V, H, self.F, self.P_prev, self.Qk, R, flt.beta, flt.m_form)
        self.lam_sum[self.ids] += lam.sum(axis=1)
        self.lam_n[self.ids] += lam.shape[1]
        return lam

    def draw(self, mean, P):
        L = self.cholesky(P)
        e = self.normal(mean.shape[1:])
        self.X = wrap_components(mean + (L @ e[..., None])[..., 0], self.model.x_angles)
        self.P, self.q_e, self.q_L, self.L = P, e, L, L

    def log_ratio(self):
        """log p(x | x_prev) - log q(x) at the drawn particles (constants 2 pi cancel)."""
        d = fast_residual(self.X, self.fx, self.model.x_angles)
        Q = self.Qk
        if is_diagonal(Q):
            q = np.diagonal(Q)
            log_prior = -0.5 * ((d * d) @ (1.0 / q) + np.log(q).sum())
        else:
            maha = np.einsum("...i,ij,...j->...", d, np.linalg.inv(Q), d)
            log_prior = -0.5 * (maha + np.linalg.slogdet(Q)[1])
        logdet = 2.0 * np.log(np.diagonal(self.q_L, axis1=-2, axis2=-1)).sum(axis=-1)
        return log_prior + 0.5 * (np.einsum("...i,...i->...", self.q_e, self.q_e) + logdet)

    def estimate(self):
        if not self.updated and not self.prior:  # predict only: draw from the prediction
            self.draw(self.mean, self.Pm)
            self.logw = self.logw + self.log_ratio()
        self.updated = True
        w, self.logw = particles.normalise(self.logw)
        x, P = particles.estimate(self.X, w, self.model.x_angles)
        self.record_ess(w)
        self.resample(w)
        return x, P


class OracleEngine(CubatureOracle, Engine):
    pass


class OracleSwarmEngine(CubatureOracle, SwarmEngine):
    """The swarm filters with the numpy GWO/IGWO move (:func:`gwo_optimize`); PSO is the library's."""

    def step(self, k, Z, finite):
        self.ancestors(k)
        return CubatureOracle.step(self, k, Z, finite)

    def move(self, zz, k, mask, meas, weigh):
        flt, m = self.flt, self.model
        if flt.optimizer == "pso":
            return super().move(zz, k, mask, meas, weigh)
        w, self.logw = particles.normalise(self.logw)
        c = particles.estimate(self.X, w, m.x_angles)[0][:, None, :]
        fit = residual_fitness(m, zz, k, mask, meas)
        if self.Fx is None:
            def fitness(Y):
                return fit(c + Y)
        else:  # posterior-type fitness
            def fitness(Y):
                return fit(c + Y) + self.transition_term(c + Y, k)
        Xr = residual(self.X, c, m.x_angles)
        Xr, _, best = gwo_optimize(Xr, fitness, self.active_rngs(), flt.t_max,
                                   flt.optimizer == "igwo", flt.a_start, flt.a_end, flt.b_start, flt.b_end, flt.xi,
                                   form=flt.a_form, movable=self.movable(k, mask))
        self.gain_sum[self.ids] += best[:, 0] - best[:, -1]
        self.moves[self.ids] += 1
        self.X = wrap_components(c + Xr, m.x_angles)
        if weigh:
            self.logw = self.loglik(zz, self.X, k, mask, meas)
            if self.Fx is not None:
                self.logw = self.logw - 0.5 * self.transition_term(self.X, k)
        self.relocated = True


def oracle_filter(name, **params):
    """The registered filter ``name`` with ``params``, its engine the numpy oracle."""
    flt = make_filter(name, **params)
    cls = OracleSwarmEngine if hasattr(flt, "optimizer") else OracleEngine
    flt.engine = lambda model, rngs: cls(flt, model, rngs)
    return flt
