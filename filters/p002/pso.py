"""Particle-swarm optimisation (PSO) as used by the PSO-PF and PSO-CPF baselines of paper 002, §4.1.

Each particle i has a position X_i, a velocity V_i (zero at the start), and a
personal best; g is the swarm's best. For t = 1..T (T = 20):

    omega(t) = omega_min + (omega_max - omega_min) exp(-alpha (t - 1)),   omega_max = 0.9, omega_min = 0.4, alpha = 0.2
    c1(t) from 2.0 down to 1.0, c2(t) from 1.5 up to 2.0   (linear in t; the paper says only "from .. to")
    V_i = omega V_i + c1 r1 (pbest_i - X_i) + c2 r2 (g - X_i),   r1, r2 uniform in [0, 1] element-wise
    X_i = clip(X_i + V_i, LB, UB)

The paper gives no velocity limit: none is applied (the bounds clip the
positions). The swarm's best fitness never worsens (recorded and asserted).
The particle filter keeps the final *positions* X_i (not the personal bests):
the swarm replaces resampling, and the positions are its population.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .swarm_kernels import pso_best, pso_velocity
from .gwo import as_runs, scaled_draws
from ..compiled import Kernel

_velocity, _best = Kernel(pso_velocity), Kernel(pso_best)

# 002, §4.1: bounds of the search for the AUV state [x, y, z, v, pitch, yaw].
LB_002 = (-300.0, -300.0, -300.0, 0.0, -np.pi / 2, -np.pi)
UB_002 = (300.0, 300.0, 0.0, 10.0, np.pi / 2, np.pi)


def below_box(states: np.ndarray, axis: int = 2, lower=LB_002) -> float:
    """The share of ``states`` (n, d) below the search box's ``lower`` bound on ``axis``; by default the depth z
    under -300 m (002 §4.1), where a truth leaves the box the swarm's positions are clipped to."""
    return float(np.mean(np.asarray(states)[:, axis] < lower[axis]))


def inertia(t: int, omega_max: float = 0.9, omega_min: float = 0.4, alpha: float = 0.2) -> float:
    """omega(t) = omega_min + (omega_max - omega_min) exp(-alpha (t - 1)), t = 1, 2, ..."""
    return omega_min + (omega_max - omega_min) * np.exp(-alpha * (t - 1))


def ramp(t: int, iterations: int, start: float, end: float) -> float:
    """Linear schedule from ``start`` (t = 1) to ``end`` (t = iterations)."""
    return start + (end - start) * (t - 1) / max(iterations - 1, 1)


@dataclass(frozen=True)
class Coefficients:
    """PSO's coefficients: the inertia weight from ``omega_max`` to ``omega_min`` (:func:`inertia`, ``alpha``)
    and the acceleration coefficients ``c1``, ``c2`` ramped from their first to their second value (:func:`ramp`)."""

    omega_max: float = 0.9
    omega_min: float = 0.4
    alpha: float = 0.2
    c1: tuple = (2.0, 1.0)
    c2: tuple = (1.5, 2.0)


def optimize(X: np.ndarray, fitness, rng, iterations: int = 20, project=None, movable=None, **coefficients):
    """Run PSO on positions ``X`` (N, d); ``project`` maps positions into the bounds; ``movable``
    (M, d) bool (None: all): the components the particles move in (velocity 0 in the others);
    ``coefficients``: the fields of :class:`Coefficients` (one record; an unknown name is a TypeError).

    Returns final positions, their fitness, and the swarm's best fitness before
    and after each iteration (non-increasing). Batched like
    the GWO move: ``X`` (M, N, d) with M generators.
    Each swarm draws its (iterations, 2, N, d) uniforms in one call. The array passes of an
    iteration are compiled (:func:`replay.filters.p002.swarm_kernels.pso_velocity`,
    :func:`replay.filters.p002.swarm_kernels.pso_best`: numpy's operations in numpy's order, so
    the numbers of the numpy reading kept as the test oracle ``tests/oracle_p002.py``, bit for
    bit); ``fitness`` and ``project`` are called between them.
    """
    c = Coefficients(**coefficients)
    X, rngs, fitness, project, single = as_runs(X, rng, fitness, project)
    M = len(X)
    keep = None if movable is None else np.ascontiguousarray(np.asarray(movable, float).reshape(M, -1))
    if project is not None:
        X = project(X)
    X = np.array(X, dtype=float, order="C")  # moved in place: never the caller's array
    f = _fit(fitness, X)
    pbest, pf = X.copy(), f.copy()
    g = np.empty(M, np.int64)
    V = np.zeros_like(X)
    best = np.empty((iterations + 1, M))  # rows: contiguous for the kernel; transposed on return
    _best(X, f, pbest, pf, g, best[0])  # f = pf: only the swarm's best
    t = np.arange(1, iterations + 1)
    w = inertia(t, c.omega_max, c.omega_min, c.alpha)
    scales = np.stack([ramp(t, iterations, *c.c1), ramp(t, iterations, *c.c2)], axis=1)  # (iterations, 2)
    R = scaled_draws(rngs, (iterations, 2) + X.shape[1:], scales)  # (M, iterations, 2, N, d): c1(t) r1, c2(t) r2
    for i in range(iterations):  # V = w V + c1 r1 (pbest - X) + c2 r2 (g - X); X = X + V
        _velocity(V, X, pbest, g, R, i, float(w[i]), keep)
        if project is not None:
            X = np.ascontiguousarray(project(X), dtype=float)
        f = _fit(fitness, X)
        _best(X, f, pbest, pf, g, best[i + 1])
    best = best.T
    if not np.isfinite(best).all():  # a particle that is not finite: the run's numerical divergence
        raise FloatingPointError("PSO fitness not finite (a particle's state is not finite)")
    assert np.all(np.diff(best, axis=1) <= 0), "PSO global best got worse"
    return (X[0], f[0], best[0]) if single else (X, f, best)


def _fit(fitness, X):
    return np.ascontiguousarray(fitness(X), dtype=float)
