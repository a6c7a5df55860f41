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

Ablations (parameters, defaults = the reading above; docs/reproduction/002.md):
``move_components="observed"`` moves the wolves only in the state components the
measured h depends on (the non-zero columns of H at the run's particles: x, y, z
of the sonar), leaving speed, pitch and yaw as drawn; ``fitness="posterior"``
adds each particle's transition term (x - f(x^i_{k-1}))' Q^-1 (x - f(x^i_{k-1}))
to the residual (a posterior-type fitness, -2 log p(z | x) p(x | x^i_{k-1}) up to
constants; the weights after the move are then exp(-f / 2)); ``a_form="printed"``
takes the IGWO convergence factor as printed (:func:`replay.filters.p002.gwo.a_sigmoid`).

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
from replay.util.params import Param
from replay.model import is_diagonal, remap_indices

from .. import particles
from ..compiled import Kernel, split
from . import compiled_util, gwo, pso
from .stack import fast_residual, wrap_inplace
from .stckf import STCKF_PARAMS
from .stcpf import CubatureParticleFilter, Engine, bound_kernels

OPTIMIZERS = ("gwo", "igwo", "pso")
GWO_PARAMS = (
    Param("a_start", float, 2.0, "GWO convergence factor a at the first iteration (002 §3.1)", low=0.0),
    Param("a_end", float, 0.0, "GWO convergence factor a at the last iteration", low=0.0),
    Param("b_start", float, 1.0, "IGWO sigmoid steepness b at the last iteration (002 §3.2.1; not printed)", low=0.0),
    Param("b_end", float, 0.5, "IGWO sigmoid steepness b at the first iteration (not printed)", low=0.0),
    Param("xi", float, 1e-4, "floor of the IGWO entropy weights (002 §3.2.2)", low=1e-6, high=1e-3),
    Param(
        "a_form",
        str,
        "centred",
        "IGWO convergence factor: the centred sigmoid (our reading) or the formula as printed (002 §3.2.1)",
        choices=("centred", "printed"),
    ),
)
PSO_PARAMS = (
    Param("omega_max", float, 0.9, "PSO inertia at the first iteration (002 §4.1)", low=0.0),
    Param("omega_min", float, 0.4, "PSO inertia limit", low=0.0),
    Param(
        "omega_decay", float, 0.2, "PSO inertia decay rate alpha: omega_min + (max - min) exp(-alpha (t - 1))", low=0.0
    ),
    Param("c1", list, (2.0, 1.0), "PSO cognitive coefficient, from .. to (linear in t)", length=2),
    Param("c2", list, (1.5, 2.0), "PSO social coefficient, from .. to (linear in t)", length=2),
    Param(
        "lower", list, pso.LB_002, "PSO search lower bounds (002 §4.1), used when as long as the state", optional=True
    ),
    Param(
        "upper", list, pso.UB_002, "PSO search upper bounds (002 §4.1), used when as long as the state", optional=True
    ),
)
STCKF_NAMES = tuple(p.name for p in STCKF_PARAMS)
PROPOSAL_NAMES = STCKF_NAMES + ("prior_cov",)  # what only a cubature proposal uses
GWO_NAMES = tuple(p.name for p in GWO_PARAMS)
PSO_NAMES = tuple(p.name for p in PSO_PARAMS)


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
    """A particle filter whose resampling is a GWO, IGWO or PSO optimisation of the particles.

    ``resampling`` / ``ess_threshold`` act only on steps without a measurement (nothing to optimise).
    One engine: the compiled kernels for the cubature proposal and the GWO/IGWO move (no
    ``compiled`` parameter), so those need a model with :meth:`replay.model.Model.kernels`.

    Bit-reproducible like every filter here (each run draws from its own seeded streams: two
    processes, one with one thread and one with two, give the same bits in every leaderboard
    column, 20 runs on sim/auv-sonar and sim/ungm), so ``replay rerun`` compares them exactly.
    """

    name = "swarm-pf"
    PARAMS = (
        *CubatureParticleFilter.PARAMS[:2],
        Param("optimizer", str, "igwo", "what replaces resampling", choices=OPTIMIZERS),
        Param("t_max", int, 20, "optimiser iterations per step (002: T_max = 20; PSO: its 'iterations')", low=0),
        Param(
            "estimate_at",
            str,
            "after",
            "estimate from the particles after the optimiser moved them (weighted by the likelihood) or before",
            choices=("after", "before"),
        ),
        Param(
            "move_components",
            str,
            "all",
            "state components the optimiser moves: all, or only those "
            "the measurement depends on (observed: non-zero columns of H)",
            choices=("all", "observed"),
        ),
        Param(
            "fitness",
            str,
            "residual",
            "optimiser fitness: the measurement residual (002) or the residual "
            "plus the particle's transition term (posterior)",
            choices=("residual", "posterior"),
        ),
        *GWO_PARAMS,
        *PSO_PARAMS,
        *CubatureParticleFilter.PARAMS[2:],
    )

    def check(self):
        p, owner = self.params(), self.owner()
        if "a_start" in p and not p["a_start"] >= p["a_end"]:
            raise ReplayError(f"{owner}: a_end must be <= a_start = {p['a_start']:g} (got {p['a_end']:g})")
        if self.optimizer != "pso":
            return
        if self.t_max < 1:
            raise ReplayError(f"{owner}: t_max must be an integer >= 1 for PSO (got {self.t_max})")
        if not p["omega_min"] <= p["omega_max"]:
            raise ReplayError(f"{owner}: omega_min must be <= omega_max = {p['omega_max']:g} (got {p['omega_min']:g})")
        lo, hi = p["lower"], p["upper"]
        if (lo is None) != (hi is None):
            raise ReplayError(
                f"{owner}: lower and upper must be given together or both null (got lower={lo}, upper={hi})"
            )
        if lo is not None:
            if len(lo) != len(hi):
                raise ReplayError(f"{owner}: lower and upper must have one length (got {len(lo)} and {len(hi)})")
            bad = [i for i, (a, b) in enumerate(zip(lo, hi)) if not a < b]
            if bad:
                i = bad[0]
                raise ReplayError(
                    f"{owner}: lower must be < upper in every component "
                    f"(component {i}: lower {lo[i]:g} >= upper {hi[i]:g})"
                )

    def engine(self, model, rngs):
        return SwarmEngine(self, model, rngs)

    def needs_kernels(self) -> bool:
        """The cubature proposal or the GWO/IGWO move is compiled; only PSO on the prior is not."""
        return self.proposal != "prior" or self.optimizer != "pso"


class SwarmEngine(Engine):
    """M runs x N particles of a :class:`SwarmParticleFilter` (see :class:`replay.filters.p002.stcpf.Engine`).

    The GWO/IGWO move is the compiled :func:`replay.filters.p002.compiled.swarm_move` (the
    library's only GWO/IGWO move; its numpy reading is the test oracle ``tests/oracle_p002.py``);
    PSO is :func:`replay.filters.p002.pso.optimize` (numpy, the only PSO).
    """

    def start(self, X0, P0):
        super().start(X0, P0)
        flt, n = self.flt, self.model.nx
        self.relocated, self.pending = False, None
        M = len(self.rngs)
        self.gain_sum, self.moves = np.zeros(M), np.zeros(M, int)
        use = flt.optimizer == "pso" and flt.lower is not None and len(flt.lower) == n
        self.bounds = (np.asarray(flt.lower), np.asarray(flt.upper)) if use else None
        if flt.optimizer != "pso":
            self.k_swarm = Kernel(bound_kernels(self.kern).swarm_move)
            self.schedule = gwo.schedule(
                flt.t_max, flt.optimizer == "igwo", flt.a_start, flt.a_end, flt.b_start, flt.b_end, flt.a_form
            )
        self.Fx = None

    def step(self, k, Z, finite):
        self.ancestors(k)
        return super().step(k, Z, finite)

    def ancestors(self, k):
        """Each particle's f(x_{k-1}) before the step moves it, for the transition term of the
        posterior-type fitness (``Fx``; None with the residual fitness)."""
        if self.flt.fitness == "posterior":
            self.Fx = np.ascontiguousarray(wrap_components(self.model.f(self.X, k), self.model.x_angles))

    def movable(self, k, mask):
        """(M, n) bool: the components the optimiser moves, per active run (None: all). ``observed``:
        the non-zero columns of the measured rows of H at any of the run's particles."""
        if self.flt.move_components == "all":
            return None
        H = self.model.H(self.X, k)
        if mask is not None:
            H = H[..., mask, :]
        return np.ascontiguousarray((H != 0).any(axis=(1, 2)))

    def relocate(self, zz, k, mask, meas):
        if self.flt.estimate_at == "after":  # move, then weigh by the likelihood at the new positions
            self.move(zz, k, mask, meas, weigh=True)
        else:  # the estimate first, from the importance weights: the move follows it (:meth:`resample`)
            self.pending = (zz, k, mask, meas)

    def move(self, zz, k, mask, meas, weigh):
        """The optimiser's move of every active run's particles; with ``weigh`` the new log weights
        log p(z | x). GWO/IGWO: :meth:`compiled_move`; PSO: :meth:`pso_move`."""
        if self.flt.optimizer == "pso":
            self.pso_move(zz, k, mask, meas)
            if weigh:
                self.logw = self.loglik(zz, self.X, k, mask, meas)
                if self.Fx is not None:
                    self.logw = self.logw - 0.5 * self.transition_term(self.X, k)
        else:
            self.compiled_move(zz, k, mask, meas)
        self.relocated = True

    def transition_term(self, X, k):
        """(x - f(x^i_{k-1}))' Q^-1 (x - f(x^i_{k-1})) of each particle (wrapped angles): the term the
        posterior-type fitness adds to the residual."""
        d = fast_residual(X, self.Fx, self.model.x_angles)
        return np.einsum("...i,ij,...j->...", d, np.linalg.inv(self.model.process_cov(k)), d)

    def pso_move(self, zz, k, mask, meas):
        flt, m = self.flt, self.model
        w, self.logw = particles.normalise(self.logw)
        c = particles.estimate(self.X, w, m.x_angles)[0][:, None, :]
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

        if self.Fx is not None:  # posterior-type fitness: plus the transition term of each particle

            def fitness(Xr, fit=fitness):
                return fit(Xr) + self.transition_term(c + Xr, k)

        Xr = residual(self.X, c, m.x_angles)
        Xr, _, best = pso.optimize(
            Xr,
            fitness,
            self.active_rngs(),
            flt.t_max,
            project,
            self.movable(k, mask),
            omega_max=flt.omega_max,
            omega_min=flt.omega_min,
            alpha=flt.omega_decay,
            c1=flt.c1,
            c2=flt.c2,
        )
        self.gain_sum[self.ids] += best[:, 0] - best[:, -1]
        self.moves[self.ids] += 1
        self.X = wrap_components(c + Xr, m.x_angles)

    def compiled_move(self, zz, k, mask, meas):
        """GWO/IGWO on every run's particles and their new log weights log p(z | x) (Gaussian), by
        :func:`replay.filters.p002.compiled.swarm_move`: per run, the wolves are the particles
        centred on their weighted mean; the uniforms are drawn from the run's own generator."""
        flt, m = self.flt, self.model
        M, N, n = self.X.shape
        rngs = self.active_rngs()
        shape = (flt.t_max, 2, min(3, N), N, n)
        best = np.empty((M, flt.t_max + 1))
        Ri, logdet_R = self.constants("R", meas[0])
        zidx = None if mask is None else np.flatnonzero(mask)  # None: all (no gather in the kernel)
        Qi = self.constants("Q", m.process_cov(k))[0] if self.Fx is not None else None
        zang = self.zmask if mask is None else self.zmask[zidx]
        fit = compiled_util.Fit(np.ascontiguousarray(zz, float), Ri, zang, self.xmask, logdet_R, m.nz)
        post = None if self.Fx is None else (self.Fx, Qi)
        args = (np.asarray(m.kernel_params(k)[1], float), self.X, self.logw, fit, zidx, self.movable(k, mask), post)
        search = (compiled_util.Gwo(self.schedule, flt.optimizer == "igwo", float(flt.xi), 1e-12), best)

        def runs(start, stop):  # each run draws from its own generator, in the thread that moves it
            for j in range(start, stop):
                self.k_swarm(*args, gwo.raw_draws([rngs[j]], shape), search, (j, j + 1))

        if M == 1:  # one run: no thread to wake
            runs(0, 1)
        else:
            split(runs, M)
        if not np.isfinite(best).all():  # a particle that is not finite: the run's numerical divergence
            raise FloatingPointError("GWO fitness not finite (a particle's state is not finite)")
        assert np.all(np.diff(best, axis=1) <= 0), "GWO elitism violated: best fitness got worse"
        self.gain_sum[self.ids] += best[:, 0] - best[:, -1]
        self.moves[self.ids] += 1

    def resample(self, w):
        if self.pending is not None:
            self.move(*self.pending, weigh=False)
            self.pending = None
        if self.relocated:
            N = self.flt.n_particles
            self.logw = np.full(self.logw.shape, -np.log(N))
            self.relocated = False
        else:
            super().resample(w)

    def finish(self, m, info):
        super().finish(m, info)
        info["optimizer"] = self.flt.optimizer
        info["mean_fitness_gain"] = float(self.gain_sum[m] / self.moves[m]) if self.moves[m] else 0.0
        info["bounds"] = "paper (002 §4.1)" if self.bounds is not None else "none"
