"""Particle filter: bootstrap (Gordon, Salmond & Smith 1993) or optimal proposal, over the run axis.

For each step and run, with N particles x^i and log-weights l^i:

    propagate   x^i ~ p(x_k | x^i_{k-1})               (model.sample_f, or f + Gaussian noise from Q)
    weight      l^i += log p(z_k | x^i)                 (model.loglik, wrapped angle residuals)
    normalise   w^i = exp(l^i - max l) / sum_j exp(l^j - max l)   (log domain: no underflow)
    estimate    x^ = sum w^i x^i (circular mean for angles), P = sum w^i (x^i - x^)(x^i - x^)'
    resample    when ESS = 1 / sum (w^i)^2 < threshold * N (threshold = 1: every step)
    roughen     after resampling, x^i_j += K E_j N^(-1/d) e,  e ~ N(0, 1)   (when K > 0)

The estimate is taken before resampling (lower variance). Resampling is
systematic by default.

Proposal (``proposal``). The bootstrap draws from the motion model and weighs by the
likelihood; a measurement much sharper than the propagated spread leaves a few particles
with all the weight (the fusion task: test1.bag's odometry twist at 0.03 m/s against a
propagated velocity spread of 0.22 m/s per 0.1 s step keeps about 2 % of the particles per
step, and whatever nothing measures, the heading, then follows a few lineages: 91.9 m off and
lost in 5 of 5 runs where the odometry alone is fused). Where the measurement selects state
components, ``h(x) = sign * x[index]`` with Q and R diagonal (the kinematic models declare it:
``model.selection()``), the locally optimal proposal p(x_k | x_{k-1}, z_k) is Gaussian in
closed form (Doucet, Godsill & Andrieu 2000, §II.D) and used by default (``auto``):
each particle's measured components are drawn from the Kalman update of f(x^i) with Q by the
measurement and weighted by the predictive p(z_k | x^i_{k-1}) =
N(z; sign f(x^i), sign^2 Q + R) (:func:`replay.filters.particles.propose`); a gate
(:mod:`replay.filters.gating`) judges the predicted particles f(x^i) with Q added to the
spread; with any other model ``auto`` is the bootstrap.

The estimate is the posterior mean E[x_k | z_1..k]. When nothing measures the heading it
spreads as the declared noise says (the odometry's recorded yaw-rate variance and
``q_attitude``: 2.3 rad after 395 s on test1.bag, the EKF's own covariance says the same) and
the mean of positions over such a heading lies inside the arc: the PF then does not give an
odometry's track back (the Kalman filters' f(mean) does), a property of the declared model,
not of the particle count (``tests/test_fusion_identity.py``).

Roughening (Gordon, Salmond & Smith 1993, §4): after resampling, each state
component j gets Gaussian jitter of standard deviation K E_j N^(-1/d), E_j the
range of the particles along j and d the state dimension. It counters sample
impoverishment when the likelihood is much sharper than the prediction (e.g.
0.01 rad sonar bearings, ``sim/auv-sonar``). ``roughening = K``; 0 (the
default) is the plain bootstrap filter; the paper suggests K = 0.2.

Over runs: particles (M, N, nx), log-weights (M, N). ``model.f`` runs once on
the particles of every run; the process noise, resampling and roughening of
run m are drawn from run m's generator only (a model that overrides
``sample_f`` draws run by run), in the order propagate, resample, roughen; the
bookkeeping is :mod:`replay.filters.particles`. So M runs at once give the
numbers of M runs of one, bit for bit.

Subclasses change the weighting through :meth:`ParticleFilter.weigh` (the
weight-factor PF of paper 003 tempers the weights).
"""

from __future__ import annotations

import numpy as np

from replay.filters.case import Case
from replay.model import Model, noise_factor
from replay.util.angles import angle_mask
from replay.util.errors import ReplayError
from replay.util.params import Param

from . import gating, particles, pf_loop
from .base import Filter, on_points
from .compiled import measured_steps
from .resampling import SCHEMES


class ParticleFilter(Filter):
    """Bootstrap PF with systematic resampling, log-domain weights and optional roughening."""

    name = "pf"
    CASE = Case(params={"n_particles": 150, "roughening": 0.5})
    PARAMS = (
        Param("n_particles", int, 1000, "particles per run", low=1),
        Param("resampling", str, "systematic", "resampling scheme", choices=tuple(SCHEMES)),
        Param(
            "ess_threshold",
            float,
            1.0,
            "resample when ESS < ess_threshold * N (1: every step, 0: never)",
            low=0.0,
            high=1.0,
        ),
        Param(
            "proposal",
            str,
            "auto",
            "importance density: bootstrap (the prior), optimal (p(x_k | x_k-1, z_k) where the "
            "measurement selects state components, Q and R diagonal: Doucet et al. 2000), auto: "
            "optimal where it applies (the fusion task's kinematic models), else bootstrap",
            choices=("auto", "bootstrap", "optimal"),
        ),
        Param(
            "roughening",
            float,
            0.0,
            "roughening constant K after resampling (Gordon et al. 1993 §4; 0: off, the paper suggests 0.2)",
            low=0.0,
        ),
    )

    def engine(self, model, rngs):
        return PFEngine(self, model, rngs)

    def weigh(self, logw: np.ndarray, ll: np.ndarray):
        """Normalised ``(w, logw)`` (R, N) of the prior log-weights plus the log-likelihoods ``ll``."""
        return particles.normalise(logw + ll)


def propagate(model, X, k, rngs):
    """x^i ~ p(x_k | x^i_{k-1}) for particles ``X`` (M, N, nx) of M runs, one generator per run:
    ``model.sample_f`` run by run when the model draws its own noise, else ``f`` on every run's
    particles at once plus Gaussian noise from Q drawn from each run's generator (in run order).
    The one propagation of every bootstrap-proposal filter (pf, wf-pf, gwo-pf, igwo-pf, pso-pf)."""
    if type(model).sample_f is not Model.sample_f:
        for j, g in enumerate(rngs):
            X[j] = model.sample_f(X[j], k, g)
        return X
    Y = on_points(model.f, X, k)
    diagonal, factor, _, _ = noise_factor(model.process_cov(k))
    for j, g in enumerate(rngs):
        if diagonal:
            particles.perturb(Y[j], factor, g)
        else:
            Y[j] += g.standard_normal(Y.shape[1:]) @ factor.T
    return Y


def optimal_applies(flt, model, X0) -> bool:
    """Whether the engine uses the optimal proposal (the ``proposal`` parameter): the model
    declares a selection measurement (``model.selection()``), draws no noise of its own, weighs
    by the Gaussian likelihood, and its h is that selection at the start states
    (a wrapper that changes h is caught); ``proposal = "optimal"`` where it does not apply is
    refused, ``auto`` falls back to the bootstrap."""
    proposal = getattr(flt, "proposal", "bootstrap")  # a subclass without the parameter: the bootstrap
    if proposal == "bootstrap":
        return False
    sel = pf_loop.selection(model)
    ok = (
        sel is not None
        and type(model).sample_f is Model.sample_f
        and type(model).loglik is Model.loglik
        and np.array_equal(np.asarray(model.h(X0, 0), float), X0[:, sel[0]] * sel[1])
    )
    if not ok and proposal == "optimal":
        raise ReplayError(
            f"pf: proposal = \"optimal\" needs a model whose measurement selects state components "
            f"with diagonal Q and R (the fusion task's); {type(model).__name__} is not one: "
            "use proposal = \"auto\" or \"bootstrap\""
        )
    return ok


def identity_at_start(model, X0, P0) -> bool:
    """Whether the first step's transition is the identity on the prior (the fusion task's steps
    before the first message: dt = 0) and every P0 diagonal: then the prior's spread can be the
    first proposal's (:meth:`PFEngine.start`). Checked exactly at x0 and x0 +- one prior
    standard deviation along each axis."""
    X0, P0 = np.asarray(X0, float), np.asarray(P0, float)
    M, n = X0.shape
    d = np.diagonal(P0, axis1=1, axis2=2)
    if not np.array_equal(P0, d[:, :, None] * np.eye(n)) or (d < 0).any():
        return False
    steps = np.sqrt(d)[:, None, :] * np.concatenate([np.zeros((1, n)), np.eye(n), -np.eye(n)])[None]
    pts = X0[:, None, :] + steps
    return bool(np.array_equal(np.asarray(on_points(model.f, pts, 0), float), pts))


class PFEngine:
    """M runs of a :class:`ParticleFilter` (or a subclass): particles (M, N, nx)."""

    GATES = True  # its update gates by the particle rule (replay.filters.gating.particle_rejects)

    def __init__(self, flt, model, rngs):
        self.flt, self.model, self.rngs = flt, model, list(rngs)

    def start(self, X0, P0):
        M, N = len(X0), self.flt.n_particles
        self.optimal = optimal_applies(self.flt, self.model, X0)
        self.ids = np.arange(M)
        self.active = list(self.rngs)
        self.sd0 = None  # the first step's proposal spread, when it carries the prior (below)
        if self.optimal and identity_at_start(self.model, X0, P0):
            # x_0 = f(x_-1) + q = x_-1 + q ~ N(x0, P0 + Q_0): the first proposal draws from that prior's
            # update by z_0 (equal weights), not from N(x0, P0) particles a sharp z_0 leaves one of
            self.X = np.repeat(np.asarray(X0, float)[:, None, :], N, axis=1)
            q0 = np.diag(self.model.process_cov(0))
            self.sd0 = np.sqrt(np.diagonal(P0, axis1=1, axis2=2) + q0)
        else:
            self.X = particles.gaussian(X0, P0, N, self.rngs)
        self.logw0 = -np.log(N)
        self.logw = np.full((M, N), -np.log(N))
        self.w = np.full((M, N), 1.0 / N)
        self.resampled = [0] * M
        self.ess_sum, self.ess_steps = np.zeros(M), np.zeros(M, int)  # ESS before resampling, per run
        self.no_nis = np.full(M, np.nan), np.zeros(M, int)  # a PF records no innovation
        self.tally = gating.Tally(self.model, M)

    def keep(self, ok):
        self.ids = self.ids[ok]
        self.tally.keep(ok)
        self.sd0 = None if self.sd0 is None else self.sd0[ok]
        self.active = [self.rngs[i] for i in self.ids]
        self.X, self.logw, self.w = self.X[ok], self.logw[ok], self.w[ok]
        self.no_nis = self.no_nis[0][ok], self.no_nis[1][ok]

    def finish(self, m, info):
        info["resampled"] = int(self.resampled[m])
        self.tally.info(m, info)
        if self.ess_steps[m]:
            info["mean_ess"] = float(self.ess_sum[m] / self.ess_steps[m])

    def step(self, k, Z, finite):
        if self.optimal:
            self.propose(k, Z, finite)
        else:
            self.propagate(k)
            self.update(k, Z, finite)
        x, P = particles.estimate(self.X, self.w, self.model.x_angles)
        self.ess_sum[self.ids] += particles.ess(self.w)
        self.ess_steps[self.ids] += 1
        self.resample()
        return x, P, *self.no_nis

    def run_all(self, Z, finite):
        """Every step of every run in one compiled loop when it computes what the steps compute
        (:mod:`replay.filters.pf_loop`), else None (the steps below run): this engine itself (not a
        subclass) with the bootstrap weighting."""
        if type(self) is PFEngine and type(self.flt).weigh is ParticleFilter.weigh and not self.tally.gates:
            return pf_loop.run(self, Z, finite)
        return None

    def propagate(self, k):
        """x^i ~ p(x_k | x^i_{k-1}) for every active run (:func:`propagate`)."""
        self.X = propagate(self.model, self.X, k, self.active)

    def propose(self, k, Z, finite):
        """The optimal proposal's propagation and weighting of every active run
        (:func:`replay.filters.particles.propose`, each run from its own generator)."""
        m = self.model
        idx, sgn = (np.ascontiguousarray(a) for a in pf_loop.selection(m))
        Y = on_points(m.f, self.X, k)
        sd = np.sqrt(np.diag(m.process_cov(k)))
        sd = self.sd0 if k == 0 and self.sd0 is not None else np.broadcast_to(sd, (len(Y), len(sd)))
        rvar = np.ascontiguousarray(np.diag(m.measurement_cov(k)), dtype=float)
        zmask = np.array(angle_mask(m.z_angles, m.nz))
        ll = np.zeros(Y.shape[:2])
        finite = self.gate(k, Z, finite, Y, sgn**2 * sd[:, idx] ** 2)  # the predictive: f(x^i), Q + R
        for j, g in enumerate(self.active):
            sel = measured_steps(finite[j][None])[0]
            z = np.ascontiguousarray(Z[j], dtype=float)
            particles.propose(Y[j], np.ascontiguousarray(sd[j]), z, sel, idx, sgn, rvar, zmask, ll[j], g)
        self.X = Y
        rows = np.flatnonzero(finite.any(axis=1))
        if len(rows):
            self.w[rows], self.logw[rows] = self.flt.weigh(self.logw[rows], ll[rows])

    def update(self, k, Z, finite):
        """Weights of the runs with a measurement (missing components left out of the likelihood, and
        the components a gate rejects: :meth:`gate`)."""
        finite = self.gate(k, Z, finite)
        if finite.all():
            self.w, self.logw = self.flt.weigh(self.logw, self.loglik(k, Z, None, range(len(Z))))
            return
        rows = np.flatnonzero(finite.any(axis=1))
        if len(rows):
            self.w[rows], self.logw[rows] = self.flt.weigh(self.logw[rows], self.loglik(k, Z, finite, rows))

    def gate(self, k, Z, finite, X=None, extra=None):
        """``finite`` without the components the gates reject (:func:`replay.filters.gating.particle_rejects`,
        with the weights before this update), the rejections counted per run."""
        gates = self.tally.gates
        if gates is None:
            return finite
        finite = np.array(finite)
        for j in np.flatnonzero(finite.any(axis=1)):
            Xj = self.X[j] if X is None else X[j]
            ex = None if extra is None else extra[j]
            cut, hit = gating.particle_rejects(gates, self.model, Xj, self.w[j], Z[j], k, finite[j], ex)
            finite[j] &= ~cut
            self.tally.count[self.ids[j], hit] += 1
        return finite

    def loglik(self, k, Z, finite, rows):
        """log p(z_k | x^i) (len(rows), N) of the runs ``rows`` (``finite``: measured components)."""
        loglik, X = self.model.loglik, self.X
        masks = [None if finite is None or finite[j].all() else finite[j] for j in rows]
        if len(rows) == 1:  # no copy
            return loglik(Z[rows[0]], X[rows[0]], k, masks[0])[None]
        ll = np.empty((len(rows), X.shape[1]))
        for i, j in enumerate(rows):
            ll[i] = loglik(Z[j], X[j], k, masks[i])
        return ll

    def resample(self):
        """Resample (and roughen) the runs whose ESS < threshold * N, each from its own generator."""
        flt = self.flt
        M, N = self.w.shape
        new = {}
        for j, a in particles.resample(self.w, self.active, flt.resampling, flt.ess_threshold).items():
            Xj = self.X[j][a]
            if flt.roughening:
                particles.roughen(Xj, float(flt.roughening), self.active[j])
            new[j] = Xj
            self.w[j] = 1.0 / N
            self.logw[j] = self.logw0
            self.resampled[self.ids[j]] += 1
        if M == 1:
            if new:  # no second copy of the only run's particles
                self.X = new[0][None]
        else:
            for j, Xj in new.items():
                self.X[j] = Xj
