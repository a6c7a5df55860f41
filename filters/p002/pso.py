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

import numpy as np

from .gwo import as_runs, draws

# 002, §4.1: bounds of the search for the AUV state [x, y, z, v, pitch, yaw].
LB_002 = (-300.0, -300.0, -300.0, 0.0, -np.pi / 2, -np.pi)
UB_002 = (300.0, 300.0, 0.0, 10.0, np.pi / 2, np.pi)


def inertia(t: int, omega_max: float = 0.9, omega_min: float = 0.4, alpha: float = 0.2) -> float:
    """omega(t) = omega_min + (omega_max - omega_min) exp(-alpha (t - 1)), t = 1, 2, ..."""
    return omega_min + (omega_max - omega_min) * np.exp(-alpha * (t - 1))


def ramp(t: int, iterations: int, start: float, end: float) -> float:
    """Linear schedule from ``start`` (t = 1) to ``end`` (t = iterations)."""
    return start + (end - start) * (t - 1) / max(iterations - 1, 1)


def optimize(X: np.ndarray, fitness, rng, iterations: int = 20,
             omega_max: float = 0.9, omega_min: float = 0.4, alpha: float = 0.2,
             c1=(2.0, 1.0), c2=(1.5, 2.0), project=None, movable=None):
    """Run PSO on positions ``X`` (N, d); ``project`` maps positions into the bounds; ``movable``
    (M, d) bool (None: all): the components the particles move in (velocity 0 in the others).

    Returns final positions, their fitness, and the swarm's best fitness before
    and after each iteration (non-increasing). Batched like
    the GWO move: ``X`` (M, N, d) with M generators.
    Each swarm draws its (iterations, 2, N, d) uniforms in one call.
    """
    X, rngs, fitness, project, single = as_runs(X, rng, fitness, project)
    M = len(X)
    keep = None if movable is None else np.asarray(movable, float).reshape(M, 1, -1)
    if project is not None:
        X = project(X)
    f = fitness(X)
    pbest, pf = X.copy(), f.copy()
    rows = np.arange(M)
    g = np.argmin(pf, axis=1)
    V = np.zeros_like(X)
    best = np.empty((M, iterations + 1))
    best[:, 0] = pf[rows, g]
    t = np.arange(1, iterations + 1)
    w = inertia(t, omega_max, omega_min, alpha)
    a1, a2 = ramp(t, iterations, *c1), ramp(t, iterations, *c2)
    r = draws(rngs, (iterations, 2) + X.shape[1:])  # (M, iterations, 2, N, d)
    R1, R2 = r[:, :, 0], r[:, :, 1]  # in place: c1(t) r1, c2(t) r2 for all iterations
    R1 *= a1[:, None, None]
    R2 *= a2[:, None, None]
    for i in range(iterations):  # in place, same arithmetic order as V = w V + R1 (p - X) + R2 (g - X)
        V *= w[i]
        t = pbest - X
        t *= R1[:, i]
        V += t
        np.subtract(pbest[rows, g][:, None, :], X, out=t)
        t *= R2[:, i]
        V += t
        if keep is not None:
            V *= keep
        X = X + V
        if project is not None:
            X = project(X)
        f = fitness(X)
        better = f < pf
        np.copyto(pbest, X, where=better[..., None])
        np.copyto(pf, f, where=better)
        g = np.argmin(pf, axis=1)
        best[:, i + 1] = pf[rows, g]
    if not np.isfinite(best).all():  # a particle that is not finite: the run's numerical divergence
        raise FloatingPointError("PSO fitness not finite (a particle's state is not finite)")
    assert np.all(np.diff(best, axis=1) <= 0), "PSO global best got worse"
    return (X[0], f[0], best[0]) if single else (X, f, best)
