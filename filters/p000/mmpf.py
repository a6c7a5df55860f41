"""Multiple-model particle filter (MMPF), the baseline of paper 000.

The paper cites MMPF (its ref. 15) without equations; this is the standard
jump-Markov-system bootstrap PF (e.g. McGinnity & Irwin 2000; Ristic,
Arulampalam & Gordon 2004, ch. 11). Each particle carries a state x^i and a
motion mode m^i in {0..M-1}. Each step k:

    switch      m^i_k ~ Pi[m^i_{k-1}, :]                      (Markov switching matrix)
    propagate   x^i_k ~ p(x_k | x^i_{k-1}) + d_{m^i_k} T_k    (model.sample_f plus the mode's drift)
    weight      w^i ∝ w^i_{k-1} p(z_k | x^i_k)                (model.loglik: the model's fixed R)
    estimate    x^ = sum w^i x^i;  mode probabilities mu_m = sum_{m^i = m} w^i
    resample    states and modes together (systematic, every step by default)

A mode is a constant rate vector ``d_m`` (state units per second) added to the
model's motion. The defaults, for the depth task's state [z, v, pitch] (eq. 4):

* mode 0 "steady": eq. 4 as is (constant speed and pitch, constant depth rate);
* mode 1 "pitch-down maneuver": pitch rate +10 deg/s (nose down: diving);
* mode 2 "pitch-up maneuver": pitch rate -10 deg/s (climbing);

Pi: stay with probability ``stay`` = 0.95, switch to each other mode with
(1 - stay) / (M - 1); initial mode probabilities uniform. The drift is added
after the model step (the depth feels the new pitch from the next step on).
``T_k`` is ``model.step(k)`` when the model has it, else 1.
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import residual, weighted_mean, wrap_components
from replay.util.errors import ReplayError

from ..base import Filter
from ..resampling import SCHEMES, effective_sample_size

PITCH_RATE = float(np.deg2rad(10.0))
DEFAULT_MODES = ((0.0, 0.0, 0.0), (0.0, 0.0, PITCH_RATE), (0.0, 0.0, -PITCH_RATE))


class MultipleModelPF(Filter):
    """Jump-Markov bootstrap PF over motion modes (module docstring)."""

    name = "mmpf"

    def __init__(self, n_particles: int = 1000, modes=DEFAULT_MODES, stay: float = 0.95,
                 transition=None, resampling: str = "systematic", ess_threshold: float = 1.0):
        if not isinstance(n_particles, (int, np.integer)) or n_particles < 2:
            raise ReplayError(f"mmpf: n_particles must be an integer >= 2 (got {n_particles!r})")
        rates = np.asarray(modes, float)
        if rates.ndim != 2 or len(rates) < 1:
            raise ReplayError("mmpf: modes must be a list of rate vectors, one per mode")
        M = len(rates)
        if transition is None:
            if not 0.0 < stay <= 1.0:
                raise ReplayError(f"mmpf: stay must be in (0, 1] (got {stay!r})")
            Pi = np.full((M, M), (1.0 - stay) / max(M - 1, 1)) if M > 1 else np.ones((1, 1))
            np.fill_diagonal(Pi, stay if M > 1 else 1.0)
        else:
            Pi = np.asarray(transition, float)
        if Pi.shape != (M, M) or (Pi < 0).any() or not np.allclose(Pi.sum(axis=1), 1.0):
            raise ReplayError(f"mmpf: transition must be a {M}x{M} matrix of non-negative rows summing to 1")
        if resampling not in SCHEMES:
            raise ReplayError(f"mmpf: resampling must be one of {', '.join(SCHEMES)} (got {resampling!r})")
        if not 0.0 <= ess_threshold <= 1.0:
            raise ReplayError(f"mmpf: ess_threshold must be in [0, 1] (got {ess_threshold!r})")
        self.n_particles = int(n_particles)
        self.modes = rates.tolist()
        self.stay = stay
        self.transition = Pi.tolist()
        self.resampling = resampling
        self.ess_threshold = float(ess_threshold)
        self._rates, self._cum = rates, np.cumsum(Pi, axis=1)

    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        m, N = state.model, self.n_particles
        if self._rates.shape[1] != m.nx:
            raise ReplayError(f"mmpf: each mode needs {m.nx} rates (one per state component), "
                              f"got {self._rates.shape[1]}")
        L = np.linalg.cholesky(np.asarray(P0, float))
        state.particles = wrap_components(state.x + state.rng.standard_normal((N, m.nx)) @ L.T, m.x_angles)
        state.modes = state.rng.integers(0, len(self._rates), N)
        state.w = np.full(N, 1.0 / N)
        state.mu_sum = np.zeros(len(self._rates))
        state.resampled, state.steps = 0, 0
        state._resample = SCHEMES[self.resampling]

    def predict(self, state, k):
        m, rng = state.model, state.rng
        u = rng.random(self.n_particles)
        cum = self._cum[state.modes]
        state.modes = np.minimum((u[:, None] >= cum).sum(axis=1), len(self._rates) - 1)
        T = m.step(k) if hasattr(m, "step") else 1.0
        x = m.sample_f(state.particles, k, rng) + self._rates[state.modes] * T
        state.particles = wrap_components(x, m.x_angles)

    def update(self, state, z, k, mask):
        logw = np.log(state.w) + state.model.loglik(z, state.particles, k, mask)
        w = np.exp(logw - logw.max())
        state.w = w / w.sum()

    def estimate(self, state):
        m, w = state.model, state.w
        x = weighted_mean(state.particles, w, m.x_angles)
        D = residual(state.particles, x, m.x_angles)
        P = (D.T * w) @ D
        state.mu_sum += np.bincount(state.modes, weights=w, minlength=len(self._rates))
        state.steps += 1
        if effective_sample_size(w) < self.ess_threshold * self.n_particles:
            idx = state._resample(w, state.rng)
            state.particles, state.modes = state.particles[idx], state.modes[idx]
            state.w = np.full(self.n_particles, 1.0 / self.n_particles)
            state.resampled += 1
        return x, P

    def finish(self, state, info):
        info.update(resampled=state.resampled,
                    mean_mode_probability=(state.mu_sum / max(state.steps, 1)).tolist())
