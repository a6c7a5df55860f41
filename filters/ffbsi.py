"""``pf+ffbsi``: the bootstrap particle filter and a forward-filtering backward-simulation smoother.

The forward pass is :class:`replay.filters.pf.ParticleFilter` (same parameters, same draws
from each run's generator) stepping through its engine's steps (:class:`RecordingEngine`: the
compiled whole-run loop keeps no history), which keeps every step's particles and weights
{x^i_k, w^i_k} (after the step's resampling: the same filtering distribution). Then, for each
run, J = ``trajectories`` backward trajectories are drawn (Godsill, Doucet & West 2004;
Särkkä 2013, §11.2, the backward-simulation particle smoother):

    x~_n ~ sum_i w^i_n delta(x - x^i_n)
    for k = n-1 .. 1:  w~^i_k ∝ w^i_k N(x~_{k+1}; f(x^i_k, k+1), Q_{k+1}),   x~_k = x^i_k with probability w~^i_k

(the difference x~_{k+1} - f(x^i_k) wrapped in the model's angle components), drawn from the
run's own generator after its forward pass (so a run's numbers do not depend on its batch).
The smoothed estimate at step k is the mean (circular for angles) and covariance of the J
trajectories there; the time per step is the forward pass's plus the backward draws'.

**Cost.** Memory: every step's particles, steps × N × (nx + 1) floats per run (refused above
:data:`MAX_BYTES` in one line); time: the forward PF stepped in Python (not its compiled loop),
plus O(J N nx) per step for the backward draws (one Gaussian density per trajectory and
particle): with N = 1000 and J = 100, 10^5 densities a step. The transition density needs a
positive-definite Q and the model's own Gaussian propagation (a model that draws its own
process noise is refused).
"""

from __future__ import annotations

from time import perf_counter

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np

from replay.model import Model
from replay.util.angles import angle_mask
from replay.util.kernels import wrap
from replay.util.errors import ReplayError
from replay.util.linalg import cholesky
from replay.util.params import Param

from . import particles
from .case import Case
from .base import Estimates
from .pf import ParticleFilter, PFEngine

MAX_BYTES = 2 * 1024**3  # the forward pass's kept particles, every run of a batch


class RecordingEngine(PFEngine):
    """The PF's engine, keeping each step's particles and weights per run (keyed by the run's
    generator: a redo of the batch run by run, or carefully, starts that run's history again)."""

    def start(self, X0, P0):
        super().start(X0, P0)
        for g in self.rngs:
            self.flt.history[id(g)] = []

    def step(self, k, Z, finite):
        out = super().step(k, Z, finite)
        for j, m in enumerate(self.ids):
            self.flt.history[id(self.rngs[m])].append((self.X[j].copy(), self.w[j].copy()))
        return out


class FFBSi(ParticleFilter):
    """The bootstrap PF and forward-filtering backward-simulation (Godsill, Doucet & West 2004): J trajectories."""

    name = "pf+ffbsi"
    CASE = Case(params={"n_particles": 150, "trajectories": 20})
    OFFLINE = True  # uses every measurement of a run (replay.scoring.gap)
    PARAMS = ParticleFilter.PARAMS + (
        Param("trajectories", int, 100, "backward trajectories drawn per run (J): cost O(J N) per step", low=1),
    )

    def engine(self, model, rngs):
        if type(model).sample_f is not Model.sample_f:
            raise ReplayError(
                f"{self.owner()}: the model {type(model).__name__} draws its own process noise: "
                "no Gaussian transition density to weigh the backward draws by"
            )
        return RecordingEngine(self, model, rngs)

    def run_batch(self, model, Z, X0, P0, rngs) -> list[Estimates]:
        M, n = np.shape(Z)[:2]
        need = M * n * self.n_particles * (model.nx + 1) * 8
        if need > MAX_BYTES:
            raise ReplayError(
                f"{self.owner()}: keeping {n} steps of {self.n_particles} particles for {M} runs needs "
                f"{need / 1024**3:.1f} GB (limit {MAX_BYTES / 1024**3:.0f} GB): fewer n_particles, runs or steps"
            )
        rngs = [g if g is not None else np.random.default_rng(0) for g in rngs]
        self.history = {}
        try:
            out = super().run_batch(model, Z, X0, P0, rngs)
            return [self._smoothed(model, est, self.history[id(g)], g) for est, g in zip(out, rngs)]
        finally:
            self.history = {}

    def _smoothed(self, model, est: Estimates, hist: list, rng) -> Estimates:
        """The run's smoothed estimates over its steps before any divergence (later ones NaN)."""
        n = len(est.x) if est.diverged_at is None else est.diverged_at
        x, P = np.full_like(est.x, np.nan), np.full_like(est.P, np.nan)
        secs = 0.0
        if n:
            t0 = perf_counter()
            traj = backward_draws(model, hist[:n], int(self.trajectories), rng)
            J = traj.shape[1]
            x[:n], P[:n] = particles.estimate(traj, np.full((n, J), 1.0 / J), model.x_angles)
            secs = (perf_counter() - t0) / n
        return Estimates(x, P, est.step_seconds + secs, est.diverged_at, dict(est.info))


def backward_draws(model, hist: list, J: int, rng) -> np.ndarray:
    """J backward trajectories (steps, J, nx) through the kept particles ``hist`` [(X (N, nx), w (N,))]
    of one run (module docstring), drawn from ``rng``."""
    n = len(hist)
    X, w = hist[-1]
    mask = np.array(angle_mask(model.x_angles, X.shape[1]))
    traj = np.empty((n, J, X.shape[1]))
    traj[-1] = X[_draw(np.broadcast_to(w, (J, len(w))), rng)]
    for k in range(n - 2, -1, -1):
        X, w = hist[k]
        try:
            L = cholesky(np.asarray(model.process_cov(k + 1), float))
        except np.linalg.LinAlgError:
            raise ReplayError(
                f"filter 'pf+ffbsi': the process noise Q of step {k + 1} is not positive definite: "
                "the transition density of the backward draws does not exist"
            ) from None
        logp = np.empty((J, len(w)))
        with np.errstate(divide="ignore"):
            logw = np.log(w)
        mu = np.ascontiguousarray(model.f(X, k + 1), dtype=float)
        transition_logw(traj[k + 1], mu, np.linalg.inv(L), mask, logw, logp)
        logp -= logp.max(axis=1, keepdims=True)
        p = np.exp(logp)
        traj[k] = X[_draw(p / p.sum(axis=1, keepdims=True), rng)]
    return traj


def _draw(p: np.ndarray, rng) -> np.ndarray:
    """One index per row of the probabilities p (J, N) (inverse CDF of one uniform each)."""
    c = np.cumsum(p, axis=1)
    u = rng.random(len(p)) * c[:, -1]
    return np.minimum((c < u[:, None]).sum(axis=1), p.shape[1] - 1)


@nb.njit(cache=True)
def transition_logw(Xn, mu, Linv, mask, logw, out):
    """out[j, i] = logw[i] - |Linv d|^2 / 2, d = Xn[j] - mu[i] with the ``mask`` components wrapped: the
    log-weights of the backward draw of trajectory j (Linv = L^-1, lower, L L' = Q; the Gaussian's
    constant is the same for every i and left out)."""
    J, nx = Xn.shape
    d = np.empty(nx)
    for j in range(J):
        for i in range(mu.shape[0]):
            for a in range(nx):
                d[a] = Xn[j, a] - mu[i, a]
            wrap(d, mask)
            s = 0.0
            for a in range(nx):
                t = 0.0
                for b in range(a + 1):
                    t += Linv[a, b] * d[b]
                s += t * t
            out[j, i] = logw[i] - 0.5 * s
