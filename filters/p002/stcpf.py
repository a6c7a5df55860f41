"""Particle filters with a per-particle cubature importance density: STCPF and CPF (paper 002, §2–3.3).

Each particle i carries a sample x^i, a covariance P^i and (for the STCKF) its
own innovation matrix V^i. One step, for all particles at once (the N
cubature filters are one batched array computation, no Python loop over
particles):

    1. STCKF (or CKF) step from (x^i_{k-1}, P^i_{k-1}):  (m^i, P^i) = posterior given z_k
    2. draw       x^i_k ~ q^i = N(m^i, P^i)
    3. weight     w^i ∝ w^i_{k-1} p(z_k | x^i_k) p(x^i_k | x^i_{k-1}) / q^i(x^i_k)      (002, §2.1)
    4. relocate   :meth:`Engine.relocate`: nothing here (resampling follows the estimate);
                  IGWO / PSO in :mod:`replay.filters.p002.igwo_stcpf`
    5. estimate   weighted mean (circular for angles) and covariance (:func:`replay.filters.particles.estimate`)
    6. resample   systematic when ESS < threshold N (:func:`replay.filters.particles.resample`)

Steps 1–3 are :class:`replay.filters.p002.cubature.CubatureUpdate`.
``proposal="prior"`` gives a bootstrap PF (x^i_k ~ p(x_k | x^i_{k-1}) by
:func:`replay.filters.pf.propagate`, weight = likelihood) that shares the
relocation machinery (GWO-PF, PSO-PF).

Choices (002 leaves them open): the next step's cubature filter of particle i
starts from its sample x^i_k (not from m^i) with covariance P^i; resampling
copies x, P and V together. A predict-only step (no measurement) draws from the
predicted (m^i-, P^i-) with weight p(x | x_prev) / q(x).

Arrays: the :class:`Engine` holds M Monte Carlo runs of N particles at once,
``X`` (M, N, nx), ``P`` (M, N, nx, nx) (the engine of the filter protocol,
:meth:`replay.filters.base.Filter.run_batch`). Each run draws from its own
generator, per step, in the same order (the importance draw (N, nx), then the
relocation's draws), and every operation acts on each run's slice alone, so a
batch of M runs gives the numbers of M runs of one, bit for bit.
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import wrap_components
from replay.util.params import Param
from replay.model import Model

from .. import particles
from ..base import Filter
try:
    from ..pf import propagate
except ImportError:  # TEMPORARY (helper A2): until filters/pf.py exposes propagate(model, X, k, rngs)
    from ..pf import PFEngine

    def propagate(model, X, k, rngs):
        e = PFEngine.__new__(PFEngine)
        e.model, e.X, e.active = model, X, list(rngs)
        e.own_noise = type(model).sample_f is not Model.sample_f
        e.propagate(k)
        return e.X
from ..resampling import SCHEMES
from . import compiled_util
from .binding import bind
from .cubature import CubatureUpdate
from .parallel import Kernel
from .stack import circular_mean, fast_residual
from .stckf import STCKF_PARAMS

PROPOSALS = ("prior", "ckf", "stckf")


class CubatureParticleFilter(Filter):
    """STCPF (``proposal="stckf"``), CPF (``"ckf"``) or bootstrap PF (``"prior"``), batched over particles."""

    name = "stcpf"
    PARAMS = (
        Param("n_particles", int, 100, "particles per run (002 §4.1: N = 100)", low=1),
        Param("proposal", str, "stckf", "importance density of each particle: its STCKF or CKF posterior, "
              "or the prior (bootstrap)", choices=PROPOSALS),
        *STCKF_PARAMS,
        Param("resampling", str, "systematic", "resampling scheme", choices=tuple(SCHEMES)),
        Param("ess_threshold", float, 1.0, "resample when ESS < threshold * N (1: every step)", low=0.0, high=1.0),
        Param("compiled", bool, True, "use the numba kernels when the model has them (same numbers to "
              "rounding; false: the numpy engine)"),
    )

    def engine(self, model, rngs):
        return Engine(self, model, rngs)


class Engine(CubatureUpdate):
    """M runs x N particles of a :class:`CubatureParticleFilter` (or a subclass)."""

    def __init__(self, flt, model, rngs):
        self.flt, self.model = flt, model
        self.rngs = [r if r is not None else np.random.default_rng(0) for r in rngs]
        n = model.nx
        self.s = np.sqrt(n)
        self.prior = flt.proposal == "prior"
        self.custom_loglik = type(model).loglik is not Model.loglik
        M = len(self.rngs)
        # compiled kernels (replay.filters.p002.compiled) when the model has them and the weights are Gaussian
        self.kern = None
        if getattr(flt, "compiled", False) and not self.prior and not self.custom_loglik:
            self.kern = model.kernels()
        if self.kern is not None:
            bound = bind(self.kern)  # compiled.py with this model's kernels (see .binding)
            self.k_cubature = Kernel(bound.cubature_step)
            self.k_threads = Kernel(bound.cubature_threads)
            self.k_estimate = Kernel(compiled_util.estimate)
            self.xmask = self.angle_mask(model.x_angles, model.nx)
            self.zmask = self.angle_mask(model.z_angles, model.nz)
            self.cache = {}
        self.repairs, self.resampled = np.zeros(M, int), np.zeros(M, int)
        self.lam_sum, self.lam_n = np.zeros(M), np.zeros(M, int)

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
        self.updated = True

    def step(self, k, Z, finite):
        pattern = finite[0]
        if not (finite == pattern).all():  # the base loop then redoes the runs one by one
            raise ValueError("runs with different missing-measurement patterns cannot share a batched step")
        if self.kern is not None and pattern.all():
            self.compiled_update(Z, k)
        else:
            self.predict(k)
            if pattern.all():
                self.update(Z, k, None)
            elif pattern.any():
                self.update(Z, k, pattern)
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

    # --- runs -------------------------------------------------------------------------------
    def active_rngs(self):
        return [self.rngs[i] for i in self.ids]

    def normal(self, shape):
        """One standard-normal draw of ``shape`` per active run, from the run's own generator -> (M, *shape)."""
        rngs = self.active_rngs()
        if len(rngs) == 1:
            return rngs[0].standard_normal(shape)[None]
        return np.stack([g.standard_normal(shape) for g in rngs])

    # --- predict ----------------------------------------------------------------------------
    def predict(self, k):
        m = self.model
        self.Qk = m.process_cov(k)
        self.updated = False
        if self.prior:
            self.X = propagate(m, self.X, k, self.active_rngs())
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

    # --- relocation, estimate, resampling ---------------------------------------------------
    def relocate(self, zz, k, mask, meas):
        """Nothing: resampling follows the estimate (:meth:`resample`), as in :mod:`replay.filters.pf`."""

    def estimate(self):
        if not self.updated and not self.prior:  # predict only: draw from the prediction
            self.draw(self.mean, self.Pm)
            self.logw = self.logw + self.log_ratio()
        self.updated = True
        if self.kern is not None:
            M, N, n = self.X.shape
            x, P, w = np.empty((M, n)), np.empty((M, n, n)), np.empty((M, N))
            self.k_estimate(self.X, self.logw, self.xmask, x, P, w)
        else:
            w, self.logw = particles.normalise(self.logw)
            x, P = particles.estimate(self.X, w, self.model.x_angles)
        self.resample(w)
        return x, P

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
