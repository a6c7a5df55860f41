"""The per-particle cubature importance density of the STCPF / CPF engine (paper 002, §2.1–2.2).

:class:`CubatureUpdate` is the update half of :class:`replay.filters.p002.stcpf.Engine`:
for M runs x N particles at once, each particle's CKF or STCKF posterior
(m^i, P^i) given z_k, the draw x^i ~ N(m^i, P^i) and the importance weight

    w^i ∝ w^i_{k-1} p(z_k | x^i) p(x^i | x^i_{k-1}) / q^i(x^i)                   (002, §2.1)

in numpy (:meth:`CubatureUpdate.posterior`, :meth:`~CubatureUpdate.draw`,
:meth:`~CubatureUpdate.log_ratio`) or, when the model has numba kernels and every
measurement component is present, in one compiled call
(:meth:`CubatureUpdate.compiled_update`, :func:`replay.filters.p002.compiled.cubature_step`:
the same equations, the same draws in the same order).

Arithmetic shortcuts (exact in real arithmetic, cheaper): with cubature points
X_c = m ± sqrt(n) L e_c, the cross covariance is
P_xz = sqrt(n)/(2n) L (Z_+ - Z_-)' (no state deviations formed); the posterior
is P = P- - P_xz K' (= P- - K S K' since K S = P_xz); and the importance
density's exponent at the drawn x = m + L e is e'e (no triangular solve).

Jacobians (STCKF fading factor): the model's analytic ``F``/``H`` when the
model declares ``vector_jacobians = True`` (they accept stacks of states), else
central differences (:func:`replay.filters.p002.stckf.batched_jacobian`).
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import wrap_components
from replay.model import is_diagonal, remap_indices

from .parallel import split, threads
from .stack import batched_cholesky, circular_mean, fast_residual, solve_stack
from .stckf import batched_jacobian, fading_factor, next_V

GRAIN = 50  # particles per thread at least, in the compiled cubature step of one run
GRAIN_RUNS = 1000  # the same for batched runs
LOG2PI = np.log(2.0 * np.pi)


class CubatureUpdate:
    """Importance density, draw and weight of every particle of every active run (module docstring).

    Expects of the engine: ``flt``, ``model``, ``X``, ``P``, ``L``, ``V``, ``V_key``,
    ``logw``, ``mean``, ``Pm``, ``fx``, ``F``, ``P_prev``, ``Qk`` (set by its predict),
    ``ids``, ``repairs``, ``lam_sum``, ``lam_n``, ``normal()``, ``relocate()``.
    """

    def cholesky(self, P):
        L, bad = batched_cholesky(P)
        if bad is not None:
            self.repairs[self.ids] += bad.reshape(len(self.ids), -1).sum(axis=1)
        return L

    def points(self, X, P, L=None):
        """Cubature points X ± sqrt(n) L e_i (..., 2n, n) and the factors L (given, or of P)."""
        L = self.cholesky(P) if L is None else L
        sL = self.s * np.swapaxes(L, -1, -2)
        Xb = X[..., None, :]
        return np.concatenate([Xb + sL, Xb - sL], axis=-2), L

    def jacobian(self, analytic, fun, X, k, angles):
        """Jacobians at every particle: the model's own when it declares ``vector_jacobians``
        (F, H taking stacks of states), else central differences in one call of ``fun``."""
        if getattr(self.model, "vector_jacobians", False):
            return analytic(X, k)
        return batched_jacobian(fun, X, k, angles, self.model.jacobian_step)

    def measurement(self, k, mask):
        """Per-step constants of the measurement: R, angles, R^-1 (vector when diagonal), log det R."""
        m = self.model
        R, angles = m.measurement_cov(k), m.z_angles
        if mask is not None:
            R, angles = R[np.ix_(mask, mask)], remap_indices(angles, mask)
        if is_diagonal(R):
            r = np.diagonal(R)
            return R, angles, 1.0 / r, float(np.log(r).sum())
        return R, angles, np.linalg.inv(R), float(np.linalg.slogdet(R)[1])

    # --- numpy ----------------------------------------------------------------------------
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

    def loglik(self, zz, X, k, mask, meas):
        """log p(z | x) for every particle of every run (Gaussian, wrapped angle residuals)."""
        m = self.model
        if self.custom_loglik:
            full = np.full((len(zz), m.nz), np.nan)
            full[:, slice(None) if mask is None else mask] = zz
            return np.stack([m.loglik(full[j], X[j], k, mask) for j in range(len(X))])
        R, angles, Ri, logdet = meas
        zh = m.h(X, k)
        d = fast_residual(zz[:, None, :], zh if mask is None else zh[..., mask], angles)
        maha = (d * d) @ Ri if Ri.ndim == 1 else np.einsum("...i,ij,...j->...", d, Ri, d)
        return -0.5 * (maha + logdet + len(R) * LOG2PI)

    def posterior(self, zz, k, mask, meas):
        """Batched CKF / STCKF measurement update of every particle's (m, Pm)."""
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
        Pxz = (self.s / c) * (L @ (Dz[..., :n, :] - Dz[..., n:, :]))
        Pm = self.Pm
        if self.flt.proposal == "stckf":
            lam = self.fading(zz, k, mask, R, zang)[..., None, None]
            Pzz, Pxz = lam * Pzz, lam * Pxz
            if self.flt.scale_prior:
                Pm = lam * Pm
        S = Pzz + R
        K = np.swapaxes(solve_stack(S, np.swapaxes(Pxz, -1, -2)), -1, -2)
        y = fast_residual(zz[:, None, :], zh, zang)
        mean = wrap_components(self.mean + (K @ y[..., None])[..., 0], m.x_angles)
        P = Pm - Pxz @ np.swapaxes(K, -1, -2)
        return mean, 0.5 * (P + np.swapaxes(P, -1, -2))

    def fading(self, zz, k, mask, R, zang):
        """The STCKF fading factor of every particle (002 §2.2.2, :func:`replay.filters.p002.stckf.fading_factor`)."""
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
        """x = m + L e, e ~ N(0, I) from each run's generator; keeps what :meth:`log_ratio` needs."""
        L = self.cholesky(P)
        e = self.normal(mean.shape[1:])
        self.X = wrap_components(mean + (L @ e[..., None])[..., 0], self.model.x_angles)
        self.P, self.q_e, self.q_L = P, e, L
        self.L = L  # the next predict's cubature points need the factor of this P

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

    # --- compiled -------------------------------------------------------------------------
    def compiled_update(self, z, k):
        """The engine's predict and :meth:`update` with every measurement component present, by
        :func:`replay.filters.p002.compiled.cubature_step` (same equations, same draws, same order)."""
        m, flt = self.model, self.flt
        M, N, n = self.X.shape
        Q = self.Qk = m.process_cov(k)
        Qi, logdet_Q = self.constants("Q", Q)
        R = m.measurement_cov(k)
        Ri, logdet_R = self.constants("R", R)
        e = self.normal((N, n))
        have_L = self.L is not None
        if not have_L:
            self.L = np.empty_like(self.P)
        stckf = flt.proposal == "stckf"
        have_V = stckf and self.V is not None and self.V_key is None
        if not have_V:
            self.V, self.V_key = np.empty((M, N, m.nz, m.nz)), None
        lam = np.empty((M, N))
        rep = np.zeros((M, N), np.int64)
        pf, ph = m.kernel_params(k)
        st = (flt.rho, flt.beta, flt.m_form == "propagated", flt.scale_prior) if stckf else (1.0, 1.0, True, True)
        opts = np.array([have_L, have_V, stckf, *st, logdet_Q, logdet_R], float)
        args = (np.asarray(pf, float), np.asarray(ph, float), self.X, self.P, self.L, self.V, self.logw,
                np.ascontiguousarray(z, float), e, Q, Qi, R, Ri, self.xmask, self.zmask, opts, lam, rep)
        chunks = min(threads(), M * N // GRAIN)
        if chunks > 1 and M == 1:  # one run: numba's OpenMP threads (they spin between steps)
            self.k_threads(*args, chunks)
        else:  # runs: Python threads, each range long enough to pay for waking its thread; no spinning
            split(self.k_cubature, M * N, *args, grain=GRAIN_RUNS)
        self.repairs[self.ids] += rep.sum(axis=1)
        if stckf:
            self.lam_sum[self.ids] += lam.sum(axis=1)
            self.lam_n[self.ids] += N
        self.updated = True
        self.relocate(z, k, None, (R, m.z_angles, Ri, logdet_R))

    def constants(self, name, C):
        """(C^-1, log det C) of a covariance, recomputed only when C changes."""
        C = np.ascontiguousarray(C, float)
        key = C.tobytes()
        cached = self.cache.get(name)
        if cached is None or cached[0] != key:
            cached = self.cache[name] = (key, np.linalg.inv(C), float(np.linalg.slogdet(C)[1]))
        return cached[1], cached[2]

    @staticmethod
    def angle_mask(angles, n):
        mask = np.zeros(n, bool)
        mask[list(angles)] = True
        return mask
