"""Bootstrap particle filter (Gordon, Salmond & Smith 1993).

For each step, with N particles x^i and log-weights l^i:

    propagate   x^i ~ p(x_k | x^i_{k-1})               (model.sample_f, all particles at once)
    weight      l^i += log p(z_k | x^i)                 (model.loglik, wrapped angle residuals)
    normalise   w^i = exp(l^i - max l) / sum_j exp(l^j - max l)   (log domain: no underflow)
    estimate    x^ = sum w^i x^i (circular mean for angles), P = sum w^i (x^i - x^)(x^i - x^)'
    resample    when ESS = 1 / sum (w^i)^2 < threshold * N (threshold = 1: every step)

The estimate is taken before resampling (lower variance). Resampling is
systematic by default.

Roughening (Gordon, Salmond & Smith 1993, §4): after resampling, each state
component j gets Gaussian jitter of standard deviation K E_j N^(-1/d), E_j the
range of the particles along j and d the state dimension. It counters sample
impoverishment when the likelihood is much sharper than the prediction (e.g.
0.01 rad sonar bearings, ``sim/auv-sonar``). ``roughening = K``; 0 (the
default) is the plain bootstrap filter; the paper suggests K = 0.2.
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import residual, weighted_mean

from .base import Filter
from .resampling import SCHEMES, effective_sample_size


class ParticleFilter(Filter):
    """Bootstrap PF with systematic resampling and log-domain weights."""

    name = "pf"

    def __init__(self, n_particles: int = 1000, resampling: str = "systematic",
                 ess_threshold: float = 1.0, roughening: float = 0.0):
        from replay.util.errors import ReplayError

        if int(n_particles) < 1:
            raise ReplayError(f"pf: n_particles must be at least 1 (got {n_particles})")
        if resampling not in SCHEMES:
            raise ReplayError(f"pf: resampling must be one of {', '.join(SCHEMES)} (got {resampling!r})")
        if not 0.0 <= ess_threshold <= 1.0:
            raise ReplayError(f"pf: ess_threshold must be in [0, 1] (got {ess_threshold})")
        if roughening < 0:
            raise ReplayError(f"pf: roughening must be >= 0 (got {roughening})")
        self.n_particles = int(n_particles)
        self.resampling = resampling
        self.ess_threshold = ess_threshold
        self.roughening = roughening

    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        L = np.linalg.cholesky(np.asarray(P0, float))
        state.particles = state.x + state.rng.standard_normal((self.n_particles, len(state.x))) @ L.T
        state.logw = np.full(self.n_particles, -np.log(self.n_particles))
        state.w = np.full(self.n_particles, 1.0 / self.n_particles)
        state.resampled = 0
        state._resample = SCHEMES[self.resampling]

    def predict(self, state, k):
        state.particles = state.model.sample_f(state.particles, k, state.rng)

    def update(self, state, z, k, mask):
        logw = state.logw + state.model.loglik(z, state.particles, k, mask)
        logw -= logw.max()
        w = np.exp(logw)
        s = w.sum()
        state.w = w / s
        state.logw = logw - np.log(s)

    def estimate(self, state):
        m = state.model
        w = state.w
        x = weighted_mean(state.particles, w, m.x_angles)
        D = residual(state.particles, x, m.x_angles)
        P = (D.T * w) @ D
        if effective_sample_size(w) < self.ess_threshold * self.n_particles:
            idx = state._resample(w, state.rng)
            state.particles = state.particles[idx]
            if self.roughening:
                p = state.particles
                sd = self.roughening * np.ptp(p, axis=0) * self.n_particles ** (-1.0 / p.shape[1])
                state.particles = p + state.rng.standard_normal(p.shape) * sd
            state.w = np.full(self.n_particles, 1.0 / self.n_particles)
            state.logw = np.full(self.n_particles, -np.log(self.n_particles))
            state.resampled += 1
        return x, P

    def finish(self, state, info):
        info["resampled"] = state.resampled
