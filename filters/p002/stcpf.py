"""Particle filters with a per-particle cubature importance density: STCPF and CPF (paper 002, §2–3.3).

Each particle i carries a sample x^i, a covariance P^i and (for the STCKF) its
own innovation matrix V^i. One step, for all particles at once (the N
cubature filters are one batched array computation, no Python loop over
particles):

    1. STCKF (or CKF) step from (x^i_{k-1}, P^i_{k-1}):  (m^i, P^i) = posterior given z_k
    2. draw       x^i_k ~ q^i = N(m^i, P^i)
    3. weight     w^i ∝ w^i_{k-1} p(z_k | x^i_k) p(x^i_k | x^i_{k-1}) / q^i(x^i_k)      (002, §2.1)
    4. relocate   :meth:`Engine.relocate`: here resampling (systematic when ESS < threshold N);
                  IGWO / PSO in :mod:`replay.filters.p002.igwo_stcpf`
    5. estimate   weighted mean (circular for angles) and covariance

``proposal="prior"`` gives a bootstrap PF (x^i_k ~ p(x_k | x^i_{k-1}), weight =
likelihood) that shares the relocation machinery (GWO-PF, PSO-PF).

Choices (002 leaves them open): the next step's cubature filter of particle i
starts from its sample x^i_k (not from m^i) with covariance P^i; resampling
copies x, P and V together. A predict-only step (no measurement) draws from the
predicted (m^i-, P^i-) with weight p(x | x_prev) / q(x).

Arrays: the :class:`Engine` holds M Monte Carlo runs of N particles at once,
``X`` (M, N, nx), ``P`` (M, N, nx, nx), so that one filter step for many runs
is one array computation (:func:`replay.filters.batched.run_batched`).
``Filter.run`` of a single run is the same engine with M = 1, so batched and
one-by-one runs give the same numbers: each run draws from its own generator,
per step, in the same order (the importance draw (N, nx), then the
relocation's draws), and every operation acts on each run's slice alone.

Jacobians (STCKF fading factor): the model's analytic ``F``/``H`` when the
model declares ``vector_jacobians = True`` (they accept stacks of states), else
central differences (:func:`replay.filters.p002.stckf.batched_jacobian`).

Arithmetic shortcuts (exact in real arithmetic, cheaper): with cubature points
X_c = m ± sqrt(n) L e_c, the cross covariance is
P_xz = sqrt(n)/(2n) L (Z_+ - Z_-)' (no state deviations formed); the posterior
is P = P- - P_xz K' (= P- - K S K' since K S = P_xz); and the importance
density's exponent at the drawn x = m + L e is e'e (no triangular solve).
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import TWO_PI, index, wrap_components
from replay.util.errors import ReplayError
from replay.model import Model, is_diagonal, remap_indices

from ..base import Filter
from .binding import bind
from .parallel import Kernel, split, threads
from ..resampling import SCHEMES
from .stckf import batched_jacobian, check_params, fading_factor, next_V

PROPOSALS = ("prior", "ckf", "stckf")
GRAIN = 50  # particles per thread at least, in the compiled cubature step of one run
GRAIN_RUNS = 1000  # the same for batched runs
LOG2PI = np.log(2.0 * np.pi)


def batched_cholesky(P):
    """Lower Cholesky factors of a stack of covariances; a non-positive-definite
    one is repaired by clipping its eigenvalues. Returns (L, repairs per leading index)."""
    try:
        return np.linalg.cholesky(P), None
    except np.linalg.LinAlgError:
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        s, U = np.linalg.eigh(P)
        floor = 1e-12 * np.maximum(1.0, s.max(axis=-1, keepdims=True))
        bad = s.min(axis=-1) <= floor[..., 0]
        P = (U * np.maximum(s, floor)[..., None, :]) @ np.swapaxes(U, -1, -2)
        return np.linalg.cholesky(P), bad


def check_common(n_particles, rho, beta, proposal):
    if not (isinstance(n_particles, (int, np.integer)) and n_particles >= 1):
        raise ReplayError(f"n_particles must be an integer >= 1 (got {n_particles!r})")
    if proposal not in PROPOSALS:
        raise ReplayError(f"proposal must be one of {', '.join(PROPOSALS)} (got {proposal!r})")
    check_params(rho, beta)


def circular_mean(Y, angles):
    """Equal-weight mean over the points axis -2 (circular for the ``angles`` components)."""
    mean = np.einsum("...ci->...i", Y) * (1.0 / Y.shape[-2])
    if angles:
        i = index(tuple(angles))
        a = Y[..., i]
        mean[..., i] = np.arctan2(np.einsum("...ci->...i", np.sin(a)), np.einsum("...ci->...i", np.cos(a)))
    return mean


def wrap_inplace(x, angles):
    """Wrap the ``angles`` components of ``x`` in place: the arithmetic of
    :func:`replay.util.angles.wrap` (bit for bit) without its temporaries. Returns ``x``."""
    if angles:
        a = x[..., index(tuple(angles))]
        t = a * (1.0 / TWO_PI)
        t += 0.5
        np.floor(t, out=t)
        t *= TWO_PI
        a -= t
        if not isinstance(index(tuple(angles)), slice):  # fancy index: a is a copy
            x[..., index(tuple(angles))] = a
    return x


def fast_residual(a, b, angles):
    """``a - b`` with the ``angles`` components wrapped; equals :func:`replay.util.angles.residual`."""
    return wrap_inplace(np.subtract(a, b), angles)


def solve_stack(S, B):
    """S^-1 B for a stack of small symmetric positive-definite S (..., m, m), B (..., m, p).

    m <= 3: the explicit inverse (adjugate / determinant), a few array
    operations for the whole stack instead of one LAPACK call per matrix; a
    singular S gives non-finite values (the run is then counted as diverged).
    Larger m: ``numpy.linalg.solve``.
    """
    m = S.shape[-1]
    if m > 3:
        return np.linalg.solve(S, B)
    with np.errstate(divide="ignore", invalid="ignore"):
        if m == 1:
            return B / S
        if m == 2:
            a, b, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
            inv = np.stack([np.stack([d, -b], -1), np.stack([-b, a], -1)], -2)
            return inv @ B / (a * d - b * b)[..., None, None]
        a, b, c = S[..., 0, 0], S[..., 0, 1], S[..., 0, 2]
        e, f, i = S[..., 1, 1], S[..., 1, 2], S[..., 2, 2]
        inv = np.empty_like(S)
        inv[..., 0, 0] = e * i - f * f
        inv[..., 0, 1] = inv[..., 1, 0] = c * f - b * i
        inv[..., 0, 2] = inv[..., 2, 0] = b * f - c * e
        inv[..., 1, 1] = a * i - c * c
        inv[..., 1, 2] = inv[..., 2, 1] = b * c - a * f
        inv[..., 2, 2] = a * e - b * b
        det = a * inv[..., 0, 0] + b * inv[..., 1, 0] + c * inv[..., 2, 0]
        return inv @ B / det[..., None, None]


def weighted_mean_rows(X, w, angles):
    """Per-run weighted mean: X (M, N, n), w (M, N) summing to one per run -> (M, n)."""
    mean = np.einsum("mni,mn->mi", X, w)
    if angles:
        i = index(tuple(angles))
        a = X[..., i]
        mean[:, i] = np.arctan2(np.einsum("mni,mn->mi", np.sin(a), w), np.einsum("mni,mn->mi", np.cos(a), w))
    return mean


class CubatureParticleFilter(Filter):
    """STCPF (``proposal="stckf"``), CPF (``"ckf"``) or bootstrap PF (``"prior"``), batched over particles."""

    name = "stcpf"

    def __init__(self, n_particles: int = 100, proposal: str = "stckf", rho: float = 0.95,
                 beta: float = 1.2, m_form: str = "propagated", scale_prior: bool = True,
                 resampling: str = "systematic", ess_threshold: float = 1.0, compiled: bool = True):
        check_common(n_particles, rho, beta, proposal)
        if m_form not in ("propagated", "printed"):
            raise ReplayError(f"m_form must be 'propagated' or 'printed' (got {m_form!r})")
        if resampling not in SCHEMES:
            raise ReplayError(f"resampling must be one of {', '.join(SCHEMES)} (got {resampling!r})")
        self.n_particles, self.proposal = n_particles, proposal
        self.rho, self.beta, self.m_form, self.scale_prior = rho, beta, m_form, scale_prior
        self.resampling, self.ess_threshold = resampling, ess_threshold
        if not isinstance(compiled, (bool, np.bool_)):
            raise ReplayError(f"compiled must be true or false (got {compiled!r})")
        self.compiled = bool(compiled)

    def engine(self, model, rngs):
        """The array engine for M runs (one generator each); see :func:`replay.filters.batched.run_batched`."""
        return Engine(self, model, rngs)

    def run(self, model, z, x0, P0, rng=None):
        from ..batched import run_batched

        z = np.asarray(z, float)
        return run_batched(self, model, z[None], np.asarray(x0, float)[None], np.asarray(P0, float)[None],
                           [rng])[0]


class Engine:
    """M runs x N particles of a :class:`CubatureParticleFilter` (or a subclass)."""

    exact = True  # batched runs give the numbers of one-by-one runs

    def __init__(self, flt, model, rngs):
        self.flt, self.model = flt, model
        self.rngs = [r if r is not None else np.random.default_rng(0) for r in rngs]
        n = model.nx
        self.s = np.sqrt(n)
        self.prior = flt.proposal == "prior"
        self.custom_noise = type(model).sample_f is not Model.sample_f
        self.custom_loglik = type(model).loglik is not Model.loglik
        M = len(self.rngs)
        # compiled kernels (replay.filters.p002.compiled) when the model has them and the weights are Gaussian
        self.kern = None
        if getattr(flt, "compiled", False) and not self.prior and not self.custom_loglik:
            self.kern = model.kernels()
        if self.kern is not None:
            self.bound = bind(self.kern)  # compiled.py with this model's kernels (see .binding)
            self.k_cubature = Kernel(self.bound.cubature_step)
            self.k_threads = Kernel(self.bound.cubature_threads)
            self.k_estimate = Kernel(self.bound.estimate)
            self.xmask = self.angle_mask(model.x_angles, model.nx)
            self.zmask = self.angle_mask(model.z_angles, model.nz)
            self.cache = {}
        self.repairs, self.resampled = np.zeros(M, int), np.zeros(M, int)
        self.lam_sum, self.lam_n = np.zeros(M), np.zeros(M, int)

    # --- set-up and bookkeeping ----------------------------------------------------
    def start(self, X0, P0):
        M, n = X0.shape
        N = self.flt.n_particles
        self.ids = np.arange(M)
        self.X = np.empty((M, N, n))
        for j in range(M):
            L0 = np.linalg.cholesky(P0[j])
            self.X[j] = X0[j] + self.rngs[j].standard_normal((N, n)) @ L0.T
        wrap_components(self.X, self.model.x_angles)
        self.P = np.broadcast_to(P0[:, None], (M, N, n, n)).copy()
        self.L = None  # Cholesky factors of P when known (set by the importance draw)
        self.V, self.V_key = None, None
        self.logw = np.full((M, N), -np.log(N))
        self.updated = True

    def keep(self, ok):
        self.ids = self.ids[ok]
        for name in ("X", "P", "L", "V", "logw"):
            if getattr(self, name) is not None:
                setattr(self, name, getattr(self, name)[ok])

    def active_rngs(self):
        return [self.rngs[i] for i in self.ids]

    def normal(self, shape):
        """One standard-normal draw of ``shape`` per active run, from the run's own generator -> (M, *shape)."""
        rngs = self.active_rngs()
        if len(rngs) == 1:
            return rngs[0].standard_normal(shape)[None]
        return np.stack([g.standard_normal(shape) for g in rngs])

    def cholesky(self, P):
        L, bad = batched_cholesky(P)
        if bad is not None:
            self.repairs[self.ids] += bad.reshape(len(self.ids), -1).sum(axis=1)
        return L

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

    def step(self, rows, k, z, finite):
        if len(rows) != len(self.ids):  # a lone retry after a failure: the batch's state moved on
            raise np.linalg.LinAlgError("particle filter step failed")
        pattern = finite[0]
        if not (finite == pattern).all():
            raise ValueError("runs with different missing-measurement patterns cannot share a batched step")
        if self.kern is not None and pattern.all():
            self.compiled_update(z, k)
        else:
            self.predict(k)
            if pattern.all():
                self.update(z, k, None)
            elif pattern.any():
                self.update(z, k, pattern)
        x, P = self.estimate()
        M = len(x)
        return x, P, np.full(M, np.nan), np.zeros(M, int)

    def finish(self, m, info):
        info.pop("nis", None), info.pop("nis_dof", None)
        info["resampled"] = int(self.resampled[m])
        info["covariance_repairs"] = int(self.repairs[m])
        if self.lam_n[m]:
            info["lambda_mean"] = float(self.lam_sum[m] / self.lam_n[m])

    def jacobian(self, analytic, fun, X, k, angles):
        """Jacobians at every particle: the model's own when it declares ``vector_jacobians``
        (F, H taking stacks of states), else central differences in one call of ``fun``."""
        if getattr(self.model, "vector_jacobians", False):
            return analytic(X, k)
        return batched_jacobian(fun, X, k, angles, self.model.jacobian_step)

    # --- cubature moments ------------------------------------------------------------
    def points(self, X, P, L=None):
        """Cubature points X ± sqrt(n) L e_i (..., 2n, n) and the factors L (given, or of P)."""
        L = self.cholesky(P) if L is None else L
        sL = self.s * np.swapaxes(L, -1, -2)
        Xb = X[..., None, :]
        return np.concatenate([Xb + sL, Xb - sL], axis=-2), L

    # --- predict ---------------------------------------------------------------------
    def predict(self, k):
        m = self.model
        self.Qk = m.process_cov(k)
        self.updated = False
        if self.prior:
            if self.custom_noise:
                for j, g in enumerate(self.active_rngs()):
                    self.X[j] = m.sample_f(self.X[j], k, g)
                return
            y = m.f(self.X, k)
            e = self.normal(y.shape[1:])
            if is_diagonal(self.Qk):
                self.X = y + e * np.sqrt(np.diagonal(self.Qk))
            else:
                self.X = y + e @ np.linalg.cholesky(self.Qk).T
            return
        self.fx = m.f(self.X, k)
        self.P_prev = self.P
        pts, _ = self.points(self.X, self.P, self.L)
        Y = m.f(pts, k)
        self.mean = circular_mean(Y, m.x_angles)
        D = fast_residual(Y, self.mean[..., None, :], m.x_angles)
        self.Pm = np.swapaxes(D, -1, -2) @ D / D.shape[-2] + self.Qk
        if self.flt.proposal == "stckf":
            self.F = self.jacobian(m.F, m.f, self.X, k, m.x_angles)

    # --- update -------------------------------------------------------------------------
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

    def compiled_update(self, z, k):
        """:meth:`predict` and :meth:`update` with every measurement component present, by
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
        opts = np.array([have_L, have_V, stckf, flt.rho, flt.beta, flt.m_form == "propagated", flt.scale_prior,
                         logdet_Q, logdet_R], float)
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

    # --- relocation (resampling) and estimate -------------------------------------
    def relocate(self, zz, k, mask, meas):
        """Resampling happens in :meth:`estimate` (after the estimate, as in :mod:`.pf`)."""

    def normalise(self):
        lw = self.logw - self.logw.max(axis=1, keepdims=True)
        w = np.exp(lw)
        s = w.sum(axis=1, keepdims=True)
        self.logw = lw - np.log(s)
        return w / s

    def estimate(self):
        m = self.model
        if not self.updated and not self.prior:  # predict only: draw from the prediction
            self.draw(self.mean, self.Pm)
            self.logw = self.logw + self.log_ratio()
        self.updated = True
        if self.kern is not None:
            M, N, n = self.X.shape
            x, P, w = np.empty((M, n)), np.empty((M, n, n)), np.empty((M, N))
            self.k_estimate(self.X, self.logw, self.xmask, x, P, w)
        else:
            w = self.normalise()
            x = weighted_mean_rows(self.X, w, m.x_angles)
            D = fast_residual(self.X, x[:, None, :], m.x_angles)
            P = np.swapaxes(D * w[..., None], -1, -2) @ D
        self.after_estimate(w)
        return x, P

    def after_estimate(self, w):
        flt = self.flt
        N = flt.n_particles
        ess = 1.0 / np.einsum("mn,mn->m", w, w)
        for j in np.flatnonzero(ess < flt.ess_threshold * N):
            idx = SCHEMES[flt.resampling](w[j], self.rngs[self.ids[j]])
            self.X[j] = self.X[j][idx]
            if not self.prior:
                self.P[j] = self.P[j][idx]
                if self.L is not None:
                    self.L[j] = self.L[j][idx]
            if self.V is not None:
                self.V[j] = self.V[j][idx]
            self.logw[j] = -np.log(N)
            self.resampled[self.ids[j]] += 1

