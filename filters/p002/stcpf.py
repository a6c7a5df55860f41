"""Particle filters with a per-particle cubature importance density: STCPF and CPF (paper 002, §2–3.3).

Each particle i carries a sample x^i, a covariance P^i and (for the STCKF) its
own innovation matrix V^i. One step, for all particles at once:

    1. STCKF (or CKF) step from (x^i_{k-1}, P^i_{k-1}):  (m^i, P^i) = posterior given z_k
    2. draw       x^i_k ~ q^i = N(m^i, P^i)
    3. weight     w^i ∝ w^i_{k-1} p(z_k | x^i_k) p(x^i_k | x^i_{k-1}) / q^i(x^i_k)      (002, §2.1)
    4. relocate   :meth:`Engine.relocate`: nothing here (resampling follows the estimate);
                  IGWO / PSO in :mod:`replay.filters.p002.igwo_stcpf`
    5. estimate   weighted mean (circular for angles) and covariance
    6. resample   systematic when ESS < threshold N (:func:`replay.filters.particles.resample`)

Steps 1–3 are one compiled call, :func:`replay.filters.p002.compiled.cubature_step`
(the library's only implementation of them: there is no numpy engine and no
``compiled`` parameter; a readable numpy version is kept as a test oracle in
``tests/oracle_p002.py``). So these filters need a model with numba kernels
(:meth:`replay.model.Model.kernels`) and the Gaussian likelihood of
:meth:`replay.model.Model.loglik`; any other model is refused when the engine
is built, in one line. ``proposal="prior"`` gives a bootstrap PF
(x^i_k ~ p(x_k | x^i_{k-1}) by :func:`replay.filters.pf.propagate`, weight =
likelihood) that shares the relocation machinery (GWO-PF, PSO-PF) and needs
no kernels.

Choices (002 leaves them open): the next step's cubature filter of particle i
starts from its sample x^i_k (not from m^i) with covariance P^i; resampling
copies x, P and V together. That is the unscented-PF reading (van der Merwe et
al. 2000): P^i is propagated as a filter covariance, F P^i F' + Q, although the
transition from the fixed sample x^i has covariance Q alone, so the proposal is
wider than the prior it is weighed against and the importance weights are
uneven (ESS below N/2 at every step on sim/auv-sonar: docs/reproduction/002.md).
``prior_cov="transition"`` predicts each particle with its transition density
N(f(x^i), Q) instead (the Gaussian approximation of the optimal importance
density p(x_k | x^i_{k-1}, z_k)); the fading factor's propagated M is then 0
(lambda = 1). The ESS of the weights the estimate uses is recorded per step,
``info["ess"]``. A predict-only step (no measurement) draws from the
predicted (m^i-, P^i-) with weight p(x | x_prev) / q(x). Missing measurement
components: the update uses the measured rows of h, R and S; the STCKF's V
restarts when the set of measured components changes.

Arrays: the :class:`Engine` holds M Monte Carlo runs of N particles at once,
``X`` (M, N, nx), ``P`` (M, N, nx, nx) (the engine of the filter protocol,
:meth:`replay.filters.base.Filter.run_batch`). Each run draws from its own
generator, per step, in the same order (the importance draw (N, nx), then the
relocation's draws), and every operation acts on each run's slice alone, so a
batch of M runs gives the numbers of M runs of one, bit for bit.
"""

from __future__ import annotations

import numpy as np

from replay.filters.case import Case
from replay.util.angles import wrap_components
from replay.util.errors import ReplayError
from replay.util.kernels import LOG_2PI, gauss_logpdf
from replay.util.params import Param
from replay.model import Model, is_diagonal, remap_indices

from .. import particles
from ..base import Filter
from ..pf import propagate
from ..resampling import SCHEMES
from ..compiled import Kernel, bind, split, threads
from . import compiled, compiled_util
from .stack import fast_residual
from .stckf import STCKF_PARAMS

PROPOSALS = ("prior", "ckf", "stckf")
GRAIN = 50  # particles per thread at least, in the compiled cubature step of one run
GRAIN_RUNS = 1000  # the same for batched runs


def bound_kernels(kernels):
    """:mod:`.compiled` bound to the model kernels ``(f, h, F, H)`` (:func:`replay.filters.compiled.bind`)."""
    return bind(compiled, kernels, "the paper-002 filter kernels (about 20-40 s)")


class CubatureParticleFilter(Filter):
    """STCPF (``proposal="stckf"``), CPF (``"ckf"``) or bootstrap PF (``"prior"``), batched over particles.

    One engine, the compiled kernels (no ``compiled`` parameter): the cubature
    proposals need a model with :meth:`replay.model.Model.kernels`.
    """

    name = "stcpf"
    CASE = Case(params={"n_particles": 12})
    PARAMS = (
        Param("n_particles", int, 100, "particles per run (002 §4.1: N = 100)", low=1),
        Param(
            "proposal",
            str,
            "stckf",
            "importance density of each particle: its STCKF or CKF posterior, or the prior (bootstrap)",
            choices=PROPOSALS,
        ),
        *STCKF_PARAMS,
        Param(
            "prior_cov",
            str,
            "propagated",
            "prediction of each particle: the cubature prediction of "
            "(x^i, P^i) (propagated, as the UPF) or the transition density N(f(x^i), Q) of the fixed "
            "sample (transition)",
            choices=("propagated", "transition"),
        ),
        Param("resampling", str, "systematic", "resampling scheme", choices=tuple(SCHEMES)),
        Param("ess_threshold", float, 1.0, "resample when ESS < threshold * N (1: every step)", low=0.0, high=1.0),
    )

    def engine(self, model, rngs):
        return Engine(self, model, rngs)

    def needs_kernels(self) -> bool:
        """True when a step calls the compiled kernels (the cubature proposal; GWO/IGWO in subclasses)."""
        return self.proposal != "prior"


class Engine:
    """M runs x N particles of a :class:`CubatureParticleFilter` (or a subclass)."""

    def __init__(self, flt, model, rngs):
        self.flt, self.model = flt, model
        self.rngs = [r if r is not None else np.random.default_rng(0) for r in rngs]
        self.prior = flt.proposal == "prior"
        self.custom_loglik = type(model).loglik is not Model.loglik
        self.kern = None
        if flt.needs_kernels():
            self.kern = model.kernels()
            if self.kern is None:
                raise ReplayError(
                    f"{flt.name} needs a model with compiled kernels (Model.kernels()); {type(model).__name__} has none"
                )
            if self.custom_loglik:
                raise ReplayError(
                    f"{flt.name} needs the Gaussian likelihood of Model.loglik (its kernels weight "
                    f"with it); {type(model).__name__} overrides loglik"
                )
            self.xmask = self.angle_mask(model.x_angles, model.nx)
            self.zmask = self.angle_mask(model.z_angles, model.nz)
            self.cache = {}
        if not self.prior:
            bound = bound_kernels(self.kern)
            self.k_cubature = Kernel(bound.cubature_step)
            self.k_threads = Kernel(bound.cubature_threads)
            self.k_estimate = Kernel(compiled_util.estimate)
        M = len(self.rngs)
        self.repairs, self.resampled = np.zeros(M, int), np.zeros(M, int)
        self.lam_sum, self.lam_n = np.zeros(M), np.zeros(M, int)
        self.ess_log = []  # (active run ids, ESS of each) per step

    # --- the protocol -------------------------------------------------------------------
    def start(self, X0, P0):
        M, n = X0.shape
        N = self.flt.n_particles
        self.ids = np.arange(M)
        self.X = wrap_components(particles.gaussian(X0, P0, N, self.rngs), self.model.x_angles)
        self.P = np.broadcast_to(P0[:, None], (M, N, n, n)).copy()
        self.L = None  # Cholesky factors of P when known (set by the importance draw)
        self.V, self.V_key = None, None
        self.logw = np.full((M, N), -np.log(N))

    def step(self, k, Z, finite):
        pattern = finite[0]
        if not (finite == pattern).all():  # the base loop then redoes the runs one by one
            raise ValueError("runs with different missing-measurement patterns cannot share a batched step")
        mask = None if pattern.all() else pattern
        zz = Z if mask is None else Z[:, pattern]
        if self.prior:
            self.X = propagate(self.model, self.X, k, self.active_rngs())
            if pattern.any():
                meas = self.measurement(k, mask)
                self.logw = self.logw + self.loglik(zz, self.X, k, mask, meas)
        else:
            meas = self.cubature(zz, k, pattern)
        if pattern.any():
            self.relocate(zz, k, mask, meas)
        x, P = self.estimate()
        M = len(x)
        return x, P, np.full(M, np.nan), np.zeros(M, int)

    def keep(self, ok):
        self.ids = self.ids[ok]
        for name in ("X", "P", "L", "V", "logw"):
            if getattr(self, name) is not None:
                setattr(self, name, getattr(self, name)[ok])

    def finish(self, m, info):
        info["resampled"] = int(self.resampled[m])
        info["covariance_repairs"] = int(self.repairs[m])
        if self.lam_n[m]:
            info["lambda_mean"] = float(self.lam_sum[m] / self.lam_n[m])
        info["ess"] = np.array([e[ids == m][0] for ids, e in self.ess_log if (ids == m).any()])  # per step

    # --- runs -------------------------------------------------------------------------------
    def active_rngs(self):
        return [self.rngs[i] for i in self.ids]

    def normal(self, shape):
        """One standard-normal draw of ``shape`` per active run, from the run's own generator -> (M, *shape)."""
        rngs = self.active_rngs()
        if len(rngs) == 1:
            return rngs[0].standard_normal(shape)[None]
        return np.stack([g.standard_normal(shape) for g in rngs])

    # --- the measurement ------------------------------------------------------------------
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

    def loglik(self, zz, X, k, mask, meas):
        """log p(z | x) for every particle of every run (the model's own when it overrides
        :meth:`replay.model.Model.loglik`, else Gaussian with wrapped angle residuals)."""
        m = self.model
        if self.custom_loglik:
            full = np.full((len(zz), m.nz), np.nan)
            full[:, slice(None) if mask is None else mask] = zz
            return np.stack([m.loglik(full[j], X[j], k, mask) for j in range(len(X))])
        R, angles, Ri, logdet = meas
        zh = m.h(X, k)
        d = fast_residual(zz[:, None, :], zh if mask is None else zh[..., mask], angles)
        maha = (d * d) @ Ri if Ri.ndim == 1 else np.einsum("...i,ij,...j->...", d, Ri, d)
        return gauss_logpdf(maha + logdet, len(R) * LOG_2PI)

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

    # --- the cubature step (compiled) -----------------------------------------------------
    def cubature(self, zz, k, pattern):
        """Steps 1–3 for every particle of every active run, by
        :func:`replay.filters.p002.compiled.cubature_step`: the measured components ``pattern`` of
        z (``zz`` holds them; none: a predict-only step drawing from the prediction). Returns the
        measurement constants (R, angles, R^-1, log det R) of the measured components, or None."""
        m, flt = self.model, self.flt
        M, N, n = self.X.shape
        Q = m.process_cov(k)
        Qi, logdet_Q = self.constants("Q", Q)
        full = pattern.all()
        zidx = None if full else np.flatnonzero(pattern)  # None: all (the kernel then gathers nothing)
        nzm = m.nz if full else len(zidx)
        meas, logdet_R = None, 0.0
        if nzm:
            R = m.measurement_cov(k)
            if not full:
                R = R[np.ix_(zidx, zidx)]
            Ri, logdet_R = self.constants("R", R)
            angles = m.z_angles if full else remap_indices(m.z_angles, pattern)
            meas = (R, angles, Ri, logdet_R)
        else:
            R = Ri = np.zeros((0, 0))
        e = self.normal((N, n))
        have_L = self.L is not None
        if not have_L:
            self.L = np.empty_like(self.P)
        stckf = flt.proposal == "stckf"
        key = None if full else tuple(pattern)
        if stckf and nzm and not (self.V is not None and self.V_key == key):
            self.V, self.V_key = None, key  # V restarts when the measured components change
        have_V = stckf and self.V is not None
        V = self.V if have_V else np.empty((M, N, nzm, nzm))
        lam = np.empty((M, N))
        rep = np.zeros((M, N), np.int64)
        pf, ph = m.kernel_params(k)
        pr = compiled_util.Proposal(
            stckf=stckf,
            fading=compiled_util.Fading.of(flt) if stckf else compiled_util.Fading(1.0, 1.0, True),
            scale_prior=bool(flt.scale_prior) if stckf else True,
            have_L=have_L,
            have_V=have_V,
            transition=getattr(flt, "prior_cov", "propagated") == "transition",
            logdet_Q=float(logdet_Q),
            logdet_R=float(logdet_R),
            nzf=int(m.nz),
        )
        zang = self.zmask if full else self.zmask[zidx]
        args = (
            np.asarray(pf, float),
            np.asarray(ph, float),
            compiled_util.Particles(self.X, self.P, self.L, V, self.logw, lam, rep),
            np.ascontiguousarray(zz, float) if nzm else None,
            zidx,
            e,
            compiled_util.Noise(Q, Qi, R, Ri, self.xmask, zang),
            pr,
        )
        chunks = min(threads(), M * N // GRAIN)
        if chunks > 1 and M == 1:  # one run: numba's OpenMP threads (they spin between steps)
            self.k_threads(*args, chunks)
        else:  # runs: Python threads, each range long enough to pay for waking its thread; no spinning
            split(self.k_cubature, M * N, *args, grain=GRAIN_RUNS)
        self.repairs[self.ids] += rep.sum(axis=1)
        if stckf and nzm:
            self.V = V
            self.lam_sum[self.ids] += lam.sum(axis=1)
            self.lam_n[self.ids] += N
        return meas

    # --- relocation, estimate, resampling ---------------------------------------------------
    def relocate(self, zz, k, mask, meas):
        """Nothing: resampling follows the estimate (:meth:`resample`), as in :mod:`replay.filters.pf`."""

    def estimate(self):
        if not self.prior:
            M, N, n = self.X.shape
            x, P, w = np.empty((M, n)), np.empty((M, n, n)), np.empty((M, N))
            self.k_estimate(self.X, self.logw, self.xmask, x, P, w)
        else:
            w, self.logw = particles.normalise(self.logw)
            x, P = particles.estimate(self.X, w, self.model.x_angles)
        self.record_ess(w)
        self.resample(w)
        return x, P

    def record_ess(self, w):
        """The ESS of each active run's normalised weights ``w`` (those of the estimate): ``info["ess"]``."""
        self.ess_log.append((self.ids.copy(), particles.ess(w)))

    def resample(self, w):
        """Resample each run whose ESS < ess_threshold N; x, P, L and V follow their ancestors."""
        flt = self.flt
        N = flt.n_particles
        for j, idx in particles.resample(w, self.active_rngs(), flt.resampling, flt.ess_threshold).items():
            self.X[j] = self.X[j][idx]
            if not self.prior:
                self.P[j] = self.P[j][idx]
                if self.L is not None:
                    self.L[j] = self.L[j][idx]
            if self.V is not None:
                self.V[j] = self.V[j][idx]
            self.logw[j] = -np.log(N)
            self.resampled[self.ids[j]] += 1
