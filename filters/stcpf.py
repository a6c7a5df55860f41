"""Particle filters with a per-particle cubature importance density: STCPF and CPF (paper 002, §2–3.3).

Each particle i carries a sample x^i, a covariance P^i and (for the STCKF) its
own innovation matrix V^i. One step, for all particles at once (the N
cubature filters are one batched array computation, no Python loop over
particles):

    1. STCKF (or CKF) step from (x^i_{k-1}, P^i_{k-1}):  (m^i, P^i) = posterior given z_k
    2. draw       x^i_k ~ q^i = N(m^i, P^i)
    3. weight     w^i ∝ w^i_{k-1} p(z_k | x^i_k) p(x^i_k | x^i_{k-1}) / q^i(x^i_k)      (002, §2.1)
    4. relocate   :meth:`relocate`: here resampling (systematic when ESS < threshold N);
                  IGWO / PSO in :mod:`replay.filters.igwo_stcpf`
    5. estimate   weighted mean (circular for angles) and covariance

``proposal="prior"`` gives a bootstrap PF (x^i_k ~ p(x_k | x^i_{k-1}), weight =
likelihood) that shares the relocation machinery (GWO-PF, PSO-PF).

Choices (002 leaves them open): the next step's cubature filter of particle i
starts from its sample x^i_k (not from m^i) with covariance P^i; resampling
copies x, P and V together. A predict-only step (no measurement) draws from the
predicted (m^i-, P^i-) with weight p(x | x_prev) / q(x).
"""
from __future__ import annotations

import numpy as np

from replay.angles import residual, weighted_mean, wrap_components
from replay.errors import ReplayError
from replay.model import is_diagonal, remap_indices

from .base import Filter
from .resampling import SCHEMES, effective_sample_size
from .stckf import batched_jacobian, check_params, fading_factor, next_V

PROPOSALS = ("prior", "ckf", "stckf")
LOG2PI = np.log(2.0 * np.pi)


def batched_cholesky(P):
    """Lower Cholesky factors of a stack of covariances; a non-positive-definite
    one is repaired by clipping its eigenvalues (and counted by the caller)."""
    try:
        return np.linalg.cholesky(P), 0
    except np.linalg.LinAlgError:
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        s, U = np.linalg.eigh(P)
        floor = 1e-12 * np.maximum(1.0, s.max(axis=-1, keepdims=True))
        bad = int((s.min(axis=-1) <= floor[..., 0]).sum())
        P = (U * np.maximum(s, floor)[..., None, :]) @ np.swapaxes(U, -1, -2)
        return np.linalg.cholesky(P), bad


def check_common(n_particles, rho, beta, proposal):
    if not (isinstance(n_particles, (int, np.integer)) and n_particles >= 1):
        raise ReplayError(f"n_particles must be an integer >= 1 (got {n_particles!r})")
    if proposal not in PROPOSALS:
        raise ReplayError(f"proposal must be one of {', '.join(PROPOSALS)} (got {proposal!r})")
    check_params(rho, beta)


class CubatureParticleFilter(Filter):
    """STCPF (``proposal="stckf"``), CPF (``"ckf"``) or bootstrap PF (``"prior"``), batched over particles."""

    name = "stcpf"

    def __init__(self, n_particles: int = 100, proposal: str = "stckf", rho: float = 0.95,
                 beta: float = 1.2, m_form: str = "propagated", scale_prior: bool = True,
                 resampling: str = "systematic", ess_threshold: float = 1.0):
        check_common(n_particles, rho, beta, proposal)
        if resampling not in SCHEMES:
            raise ReplayError(f"resampling must be one of {', '.join(SCHEMES)} (got {resampling!r})")
        self.n_particles, self.proposal = n_particles, proposal
        self.rho, self.beta, self.m_form, self.scale_prior = rho, beta, m_form, scale_prior
        self.resampling, self.ess_threshold = resampling, ess_threshold

    # --- set-up -------------------------------------------------------------------
    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        m, N = state.model, self.n_particles
        n = m.nx
        L0 = np.linalg.cholesky(np.asarray(P0, float))
        state.X = wrap_components(state.x + state.rng.standard_normal((N, n)) @ L0.T, m.x_angles)
        state.P = np.broadcast_to(np.asarray(P0, float), (N, n, n)).copy()
        state.V = None
        state.logw = np.full(N, -np.log(N))
        state.xi = np.sqrt(n) * np.vstack([np.eye(n), -np.eye(n)])
        state.repairs = state.resampled = 0
        state.lam_sum, state.lam_n = 0.0, 0
        state.updated = True

    # --- batched cubature moments -------------------------------------------------
    def _points(self, state, X, P):
        L, bad = batched_cholesky(P)
        state.repairs += bad
        return X[:, None, :] + np.einsum("mj,nij->nmi", state.xi, L)

    def _moments(self, Y, angles):
        w = np.full(Y.shape[1], 1.0 / Y.shape[1])
        mean = weighted_mean(Y, w, angles)
        D = residual(Y, mean[:, None, :], angles)
        return mean, D

    # --- predict --------------------------------------------------------------------
    def predict(self, state, k):
        m = state.model
        N, n = state.X.shape
        state.Qk = m.process_cov(k)
        state.updated = False
        if self.proposal == "prior":
            state.X = m.sample_f(state.X, k, state.rng)
            return
        state.fx = m.f(state.X, k)
        state.P_prev = state.P
        pts = self._points(state, state.X, state.P)
        Y = m.f(pts.reshape(-1, n), k).reshape(pts.shape)
        state.m, D = self._moments(Y, m.x_angles)
        state.Pm = np.einsum("nmi,nmj->nij", D, D) / D.shape[1] + state.Qk
        if self.proposal == "stckf":
            state.F = batched_jacobian(m.f, state.X, k, m.x_angles, m.jacobian_step)

    # --- update -------------------------------------------------------------------------
    def update(self, state, z, k, mask):
        m = state.model
        if self.proposal == "prior":
            state.logw = state.logw + m.loglik(z, state.X, k, mask)
        else:
            mean, P = self._posterior(state, z, k, mask)
            self._draw(state, mean, P)
            state.logw = state.logw + m.loglik(z, state.X, k, mask) + self._log_ratio(state)
        state.updated = True
        self.relocate(state, z, k, mask)

    def _posterior(self, state, z, k, mask):
        """Batched CKF / STCKF measurement update of every particle's (m, Pm)."""
        m = state.model
        n = m.nx
        pts = self._points(state, state.m, state.Pm)
        Z = m.h(pts.reshape(-1, n), k).reshape(pts.shape[0], pts.shape[1], -1)
        R, zang = m.measurement_cov(k), m.z_angles
        if mask is not None:
            Z, z, R = Z[..., mask], z[mask], R[np.ix_(mask, mask)]
            zang = remap_indices(zang, mask)
        zh, Dz = self._moments(Z, zang)
        Dx = residual(pts, state.m[:, None, :], m.x_angles)
        c = 1.0 / pts.shape[1]
        Pzz = np.einsum("nmi,nmj->nij", Dz, Dz) * c
        Pxz = np.einsum("nmi,nmj->nij", Dx, Dz) * c
        Pm = state.Pm
        if self.proposal == "stckf":
            lam = self._fading(state, z, k, mask, R, zang)
            Pzz, Pxz = lam[:, None, None] * Pzz, lam[:, None, None] * Pxz
            if self.scale_prior:
                Pm = lam[:, None, None] * Pm
        S = Pzz + R
        K = np.swapaxes(np.linalg.solve(S, np.swapaxes(Pxz, 1, 2)), 1, 2)
        y = residual(z, zh, zang)
        mean = wrap_components(state.m + np.einsum("nij,nj->ni", K, y), m.x_angles)
        P = Pm - K @ S @ np.swapaxes(K, 1, 2)
        return mean, 0.5 * (P + np.swapaxes(P, 1, 2))

    def _fading(self, state, z, k, mask, R, zang):
        m = state.model
        H = batched_jacobian(m.h, state.m, k, m.z_angles, m.jacobian_step)
        zh = m.h(state.m, k)
        if mask is not None:
            H, zh = H[:, mask], zh[:, mask]
        key = None if mask is None else tuple(mask)
        if key != getattr(state, "V_mask", None):
            state.V, state.V_mask = None, key
        state.V = next_V(state.V, residual(z, zh, zang), self.rho)
        lam = fading_factor(state.V, H, state.F, state.P_prev, state.Qk, R, self.beta, self.m_form)
        state.lam_sum += float(lam.sum())
        state.lam_n += len(lam)
        return lam

    def _draw(self, state, mean, P):
        L, bad = batched_cholesky(P)
        state.repairs += bad
        e = state.rng.standard_normal(mean.shape)
        state.X = wrap_components(mean + np.einsum("nij,nj->ni", L, e), state.model.x_angles)
        state.P, state.q_mean, state.q_L = P, mean, L

    def _log_ratio(self, state, X=None):
        """log p(x | x_prev) - log q(x), at the particles ``X`` (default: the current ones)."""
        m = state.model
        X = state.X if X is None else X
        d = residual(X, state.fx, m.x_angles)
        Q = state.Qk
        if is_diagonal(Q):
            q = np.diagonal(Q)
            log_prior = -0.5 * ((d * d) @ (1.0 / q) + np.log(q).sum())
        else:
            Lq = np.linalg.cholesky(Q)
            u = np.linalg.solve(Lq, d.T)
            log_prior = -0.5 * (np.einsum("ij,ij->j", u, u) + 2.0 * np.log(np.diag(Lq)).sum())
        dq = residual(X, state.q_mean, m.x_angles)
        u = np.linalg.solve(state.q_L, dq[..., None])[..., 0]
        logdet = 2.0 * np.log(np.diagonal(state.q_L, axis1=1, axis2=2)).sum(axis=1)
        return log_prior + 0.5 * (np.einsum("ni,ni->n", u, u) + logdet)

    # --- relocation (resampling) and estimate -------------------------------------
    def relocate(self, state, z, k, mask):
        """Resampling happens in :meth:`estimate` (after the estimate, as in :mod:`.pf`)."""

    def normalise(self, state):
        lw = state.logw - state.logw.max()
        w = np.exp(lw)
        s = w.sum()
        state.logw = lw - np.log(s)
        return w / s

    def estimate(self, state):
        m = state.model
        if not state.updated and self.proposal != "prior":  # predict only: draw from the prediction
            self._draw(state, state.m, state.Pm)
            state.logw = state.logw + self._log_ratio(state)
        state.updated = True
        w = self.normalise(state)
        x = weighted_mean(state.X, w, m.x_angles)
        D = residual(state.X, x, m.x_angles)
        P = (D.T * w) @ D
        self.after_estimate(state, w)
        return x, P

    def after_estimate(self, state, w):
        N = self.n_particles
        if effective_sample_size(w) < self.ess_threshold * N:
            idx = SCHEMES[self.resampling](w, state.rng)
            state.X, state.P = state.X[idx], state.P[idx]
            if state.V is not None:
                state.V = state.V[idx]
            state.logw = np.full(N, -np.log(N))
            state.resampled += 1

    def finish(self, state, info):
        info["resampled"] = state.resampled
        info["covariance_repairs"] = state.repairs
        if state.lam_n:
            info["lambda_mean"] = state.lam_sum / state.lam_n
