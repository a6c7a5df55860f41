"""IGWO-STCPF and the swarm-optimised particle filters of paper 002 (§3.3, §4.1).

IGWO-STCPF (002, §3.3, Fig. 8) = STCPF (:mod:`replay.filters.p002.stcpf`: each
particle's importance density is an STCKF posterior) whose resampling is
replaced by an IGWO optimisation of the particle positions
(:mod:`replay.filters.p002.gwo`). The baselines share the machinery:

| filter      | importance density        | resampling replaced by |
|-------------|---------------------------|------------------------|
| igwo-stcpf  | STCKF per particle         | IGWO, T_max = 20       |
| gwo-pf      | prior (bootstrap)          | GWO                    |
| igwo-pf     | prior (bootstrap)          | IGWO                   |
| pso-pf      | prior (bootstrap)          | PSO, 20 iterations     |
| pso-cpf     | CKF per particle           | PSO, 20 iterations     |

One step, after the importance weighting and the estimate (``relocate``):

1. fitness f(x) = (z - h(x))' R^-1 (z - h(x)), the squared Mahalanobis
   measurement residual (002: "fitness from the observation residual"; the
   sonar residual mixes metres and radians, so it is normalised by R);
2. the optimiser runs in coordinates centred on the weighted particle mean
   (002, §3.3: the wolves are updated "around the state-estimate mean"): this
   makes GWO's C * X_leader term act on deviations rather than on absolute
   positions, and keeps angle components unwrapped during the search;
3. the weights are reset to 1/N: the optimiser stands in for resampling
   (002, §3.3 "IGWO replaces the traditional resampling"). A step without a
   measurement has nothing to optimise and falls back to systematic resampling.

Where the estimate is taken is not stated. ``estimate_at="after"`` (default)
moves first and takes the mean of the moved particles weighted by the
likelihood at their new positions, w ∝ p(z | x) — the loop of the usual
swarm-optimised PF code (move, weight, estimate). The importance ratio
p(x | x_prev) / q(x) is not applied to moved particles (they were not drawn
from q; evaluating a narrow per-particle q far from its mean gave a few
particles enormous weights). ``estimate_at="before"`` takes the estimate from
the importance-weighted particles before the move, as :mod:`replay.filters.pf`
takes its estimate before resampling. Measured on sim/auv-sonar (5 runs, seed
0): with 20 iterations the wolves converge onto the best-fitting particles, so
"after" makes the estimate close to the measurement-only best fit, and
"before" carries a collapsed particle set into the next step; both were worse
than the CKF there (see docs/reproduction/002.md).

PSO bounds: LB = [-300, -300, -300, 0, -pi/2, -pi], UB = [300, 300, 0, 10, pi/2, pi]
(002, §4.1) for the 6-state AUV; they are applied only when their length equals
the model's state dimension (on the 3-state Bohai position task the search is
unbounded, reported as ``info["bounds"]``).
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import residual, wrap_components
from replay.util.errors import ReplayError
from replay.model import is_diagonal, remap_indices

from . import gwo, pso
from .binding import bind
from .parallel import Kernel, split
from .stcpf import CubatureParticleFilter, Engine, fast_residual, weighted_mean_rows, wrap_inplace

OPTIMIZERS = ("gwo", "igwo", "pso")


def residual_fitness(model, z, k, mask=None, meas=None):
    """f(X) = (z - h(X))' R^-1 (z - h(X)) for an array of states (wrapped angle residuals).

    ``z`` (nz,) with ``X`` (N, nx), or per run (M, nz) with ``X`` (M, N, nx);
    ``meas`` = (R, angles, R^-1, log det R) of the step when already computed
    (:meth:`replay.filters.p002.stcpf.Engine.measurement`, masked components only).
    """
    if meas is None:
        R, angles = model.measurement_cov(k), model.z_angles
        if mask is not None:
            z, R = z[..., mask], R[np.ix_(mask, mask)]
            angles = remap_indices(angles, mask)
        Ri = 1.0 / np.diagonal(R) if is_diagonal(R) else np.linalg.inv(R)
    else:
        angles, Ri = meas[1], meas[2]
    zb = z[..., None, :] if z.ndim == 2 else z

    def fitness(X):
        zh = model.h(X, k)
        d = fast_residual(zb, zh[..., mask] if mask is not None else zh, angles)
        return (d * d) @ Ri if Ri.ndim == 1 else np.einsum("...i,ij,...j->...", d, Ri, d)

    return fitness


class SwarmParticleFilter(CubatureParticleFilter):
    """A particle filter whose resampling is a GWO, IGWO or PSO optimisation of the particles."""

    name = "swarm-pf"

    def __init__(self, n_particles: int = 100, proposal: str = "stckf", optimizer: str = "igwo",
                 t_max: int = 20, a_start: float = 2.0, a_end: float = 0.0, b_start: float = 1.0,
                 b_end: float = 0.5, xi: float = 1e-4, omega_max: float = 0.9, omega_min: float = 0.4,
                 omega_decay: float = 0.2, c1=(2.0, 1.0), c2=(1.5, 2.0),
                 lower=pso.LB_002, upper=pso.UB_002, rho: float = 0.95, beta: float = 1.2,
                 m_form: str = "propagated", scale_prior: bool = True, estimate_at: str = "after",
                 resampling: str = "systematic", ess_threshold: float = 1.0, compiled: bool = True):
        # resampling / ess_threshold: used only on steps without a measurement (nothing to optimise)
        super().__init__(n_particles, proposal, rho, beta, m_form, scale_prior, resampling, ess_threshold,
                         compiled)
        if estimate_at not in ("before", "after"):
            raise ReplayError(f"estimate must be 'before' or 'after' the optimiser (got {estimate_at!r})")
        self.estimate_at = estimate_at
        if optimizer not in OPTIMIZERS:
            raise ReplayError(f"optimizer must be one of {', '.join(OPTIMIZERS)} (got {optimizer!r})")
        gwo.check_params(t_max, a_start, a_end, xi)
        if optimizer == "pso":
            pso.check_params(t_max, omega_max, omega_min)
        lo, hi = pso.check_bounds(lower, upper)
        self.optimizer, self.t_max = optimizer, t_max
        self.a_start, self.a_end, self.b_start, self.b_end, self.xi = a_start, a_end, b_start, b_end, xi
        self.omega_max, self.omega_min, self.omega_decay = omega_max, omega_min, omega_decay
        self.c1, self.c2 = tuple(c1), tuple(c2)
        self.lower = None if lo is None else lo.tolist()
        self.upper = None if hi is None else hi.tolist()

    def engine(self, model, rngs):
        return SwarmEngine(self, model, rngs)


class SwarmEngine(Engine):
    """M runs x N particles of a :class:`SwarmParticleFilter` (see :class:`replay.filters.p002.stcpf.Engine`)."""

    def start(self, X0, P0):
        super().start(X0, P0)
        flt, n = self.flt, self.model.nx
        self.relocated, self.pending = False, None
        M = len(self.rngs)
        self.gain_sum, self.moves = np.zeros(M), np.zeros(M, int)
        use = flt.optimizer == "pso" and flt.lower is not None and len(flt.lower) == n
        self.bounds = (np.asarray(flt.lower), np.asarray(flt.upper)) if use else None
        # compiled GWO/IGWO with the model's compiled h (Gaussian weights only)
        kern = self.model.kernels() if flt.compiled and not self.custom_loglik else None
        self.k_swarm = None
        if kern is not None and flt.optimizer != "pso":
            self.k_swarm = Kernel(bind(kern).swarm_move)
            self.xmask = self.angle_mask(self.model.x_angles, n)
            self.zmask = self.angle_mask(self.model.z_angles, self.model.nz)
            self.cache = getattr(self, "cache", {})
            self.schedule = gwo.schedule(flt.t_max, flt.optimizer == "igwo", flt.a_start, flt.a_end,
                                         flt.b_start, flt.b_end)

    def relocate(self, zz, k, mask, meas):
        if self.k_swarm is not None and mask is None and self.flt.estimate_at == "after":
            self.compiled_move(zz, k, meas)
        elif self.flt.estimate_at == "after":
            self.move(zz, k, mask, meas)
            self.logw = self.loglik(zz, self.X, k, mask, meas)
        else:
            self.pending = (zz, k, mask, meas)

    def move(self, zz, k, mask, meas):
        flt, m = self.flt, self.model
        w = self.normalise()
        c = weighted_mean_rows(self.X, w, m.x_angles)[:, None, :]
        fit = residual_fitness(m, zz, k, mask, None if self.custom_loglik else meas)

        def fitness(Xr):  # h is periodic in angle components: no need to wrap before it
            return fit(c + Xr)

        project = None
        if self.bounds is not None:
            lo, hi = self.bounds

            def project(Xr):
                A = wrap_inplace(c + Xr, m.x_angles)
                np.clip(A, lo, hi, out=A)
                A -= c
                return wrap_inplace(A, m.x_angles)

        Xr = residual(self.X, c, m.x_angles)
        rngs = self.active_rngs()
        if flt.optimizer == "pso":
            Xr, _, best = pso.optimize(Xr, fitness, rngs, flt.t_max, flt.omega_max, flt.omega_min,
                                       flt.omega_decay, flt.c1, flt.c2, project)
        else:
            Xr, _, best = gwo.optimize(Xr, fitness, rngs, flt.t_max, flt.optimizer == "igwo",
                                       flt.a_start, flt.a_end, flt.b_start, flt.b_end, flt.xi)
        self.gain_sum[self.ids] += best[:, 0] - best[:, -1]
        self.moves[self.ids] += 1
        self.X = wrap_components(c + Xr, m.x_angles)
        self.relocated = True

    def compiled_move(self, zz, k, meas):
        """:meth:`move` and the new weights for a full Gaussian measurement and GWO/IGWO, by
        :func:`replay.filters.p002.compiled.swarm_move` (the same draws from the same generators)."""
        flt, m = self.flt, self.model
        M, N, n = self.X.shape
        rngs = self.active_rngs()
        shape = (flt.t_max, 2, min(3, N), N, n)
        best = np.empty((M, flt.t_max + 1))
        Ri, logdet_R = self.constants("R", meas[0])
        args = (np.asarray(m.kernel_params(k)[1], float), self.X, self.logw, np.ascontiguousarray(zz, float), Ri,
                self.xmask, self.zmask)
        opts = (self.schedule, flt.optimizer == "igwo", float(flt.xi), 1e-12, logdet_R, best)

        def runs(start, stop):  # each run draws from its own generator, in the thread that moves it
            for j in range(start, stop):
                self.k_swarm(*args, gwo.raw_draws([rngs[j]], shape), *opts, j, j + 1)

        split(runs, M)
        assert np.all(np.diff(best, axis=1) <= 0), "GWO elitism violated: best fitness got worse"
        self.gain_sum[self.ids] += best[:, 0] - best[:, -1]
        self.moves[self.ids] += 1
        self.relocated = True

    def after_estimate(self, w):
        if self.pending is not None:
            self.move(*self.pending)
            self.pending = None
        if self.relocated:
            N = self.flt.n_particles
            self.logw = np.full(self.logw.shape, -np.log(N))
            self.relocated = False
        else:
            super().after_estimate(w)

    def finish(self, m, info):
        super().finish(m, info)
        info["optimizer"] = self.flt.optimizer
        info["mean_fitness_gain"] = float(self.gain_sum[m] / self.moves[m]) if self.moves[m] else 0.0
        info["bounds"] = "paper (002 §4.1)" if self.bounds is not None else "none"


def _fixed(cls, params: dict, t_max: int) -> dict:
    """Constructor arguments of a named variant: its proposal and optimiser are fixed (a manifest
    records them, so ``replay rerun`` passes them back: accepted when equal, refused otherwise)."""
    for key, value in (("proposal", cls.PROPOSAL), ("optimizer", cls.OPTIMIZER)):
        given = params.pop(key, value)
        if given != value:
            raise ReplayError(f"{cls.name}: {key} is fixed to {value!r} (got {given!r})")
    params.setdefault("t_max", t_max)
    return dict(proposal=cls.PROPOSAL, optimizer=cls.OPTIMIZER, **params)


class IGWOSTCPF(SwarmParticleFilter):
    """IGWO-STCPF (002, §3.3): STCKF importance density, IGWO in place of resampling."""

    name, PROPOSAL, OPTIMIZER = "igwo-stcpf", "stckf", "igwo"

    def __init__(self, n_particles: int = 100, t_max: int = 20, **params):
        super().__init__(n_particles, **_fixed(type(self), dict(params, t_max=t_max), t_max))


class GWOPF(IGWOSTCPF):
    """Bootstrap PF with standard GWO in place of resampling (002, §3.2 benchmark 1)."""

    name, PROPOSAL, OPTIMIZER = "gwo-pf", "prior", "gwo"


class IGWOPF(IGWOSTCPF):
    """Bootstrap PF with IGWO in place of resampling (002, §3.2 benchmark 1)."""

    name, PROPOSAL, OPTIMIZER = "igwo-pf", "prior", "igwo"


class PSOPF(SwarmParticleFilter):
    """PSO-PF baseline (002, §4.1): bootstrap PF, PSO (20 iterations, bounded) in place of resampling.

    ``iterations`` is the PSO name of ``t_max`` (recorded as ``t_max``; either is accepted).
    """

    name, PROPOSAL, OPTIMIZER = "pso-pf", "prior", "pso"

    def __init__(self, n_particles: int = 100, iterations: int = 20, **params):
        super().__init__(n_particles, **_fixed(type(self), params, iterations))


class PSOCPF(PSOPF):
    """PSO-CPF baseline (002, §4.1): PSO-PF with a per-particle CKF importance density."""

    name, PROPOSAL, OPTIMIZER = "pso-cpf", "ckf", "pso"
