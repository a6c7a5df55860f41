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

import math

import numpy as np

from replay.filters.case import Case
from replay.util.angles import wrap_components
from replay.util.errors import ReplayError
from replay.util.params import Param

from .. import particles
from ..base import Filter
from ..resampling import SCHEMES

PITCH_RATE = float(np.deg2rad(10.0))
DEFAULT_MODES = ((0.0, 0.0, 0.0), (0.0, 0.0, PITCH_RATE), (0.0, 0.0, -PITCH_RATE))


class Rows(Param):
    """A matrix parameter: a list of rows, each a list of finite numbers, all of one length.

    (Declared as ``type=list``; the value is normalised to a tuple of tuples.)
    """

    def accepts(self) -> str:
        return "a list of rows of numbers, all of one length" + (" (or null)" if self.optional else "")

    def _coerce(self, v):
        if not isinstance(v, (list, tuple)) or not v:
            return False, v
        rows = []
        for row in v:
            if not isinstance(row, (list, tuple)) or len(row) != len(v[0]) or not row:
                return False, v
            if not all(_finite_number(x) for x in row):
                return False, v
            rows.append(tuple(float(x) for x in row))
        return True, tuple(rows)


def _finite_number(x) -> bool:
    return (
        isinstance(x, (int, float, np.integer, np.floating))
        and not isinstance(x, (bool, np.bool_))
        and math.isfinite(x)
    )


class MultipleModelPF(Filter):
    """Jump-Markov bootstrap PF over motion modes (module docstring)."""

    name = "mmpf"
    CASE = Case("sim/lake-depth", "depth", {"n_particles": 150}, first=60)
    PARAMS = (
        Param("n_particles", int, 1000, "particles N", low=2),
        Rows(
            "modes",
            list,
            DEFAULT_MODES,
            "one rate vector per motion mode (state units per second), added to the model's motion",
        ),
        Param(
            "stay",
            float,
            0.95,
            "probability of staying in a mode (when transition is null)",
            low=0.0,
            high=1.0,
            low_open=True,
        ),
        Rows(
            "transition", list, None, "Markov switching matrix Pi, rows summing to 1 (null: from stay)", optional=True
        ),
        Param("resampling", str, "systematic", "resampling scheme", choices=tuple(SCHEMES)),
        Param("ess_threshold", float, 1.0, "resample when ESS < threshold * N (1: every step)", low=0.0, high=1.0),
    )

    def check(self):
        rates = np.asarray(self.modes, float)
        M = len(rates)
        if self.transition is None:
            Pi = np.full((M, M), (1.0 - self.stay) / max(M - 1, 1)) if M > 1 else np.ones((1, 1))
            np.fill_diagonal(Pi, self.stay if M > 1 else 1.0)
        else:
            Pi = np.asarray(self.transition, float)
        if Pi.shape != (M, M) or (Pi < 0).any() or not np.allclose(Pi.sum(axis=1), 1.0):
            raise ReplayError(
                f"{self.owner()}: transition must be a {M}x{M} matrix (one row per mode) of "
                f"non-negative rows summing to 1 (got {Pi.tolist()})"
            )
        self._rates, self._cum = rates, np.cumsum(Pi, axis=1)

    def params(self) -> dict:
        """As declared, with the matrices as lists of lists (as a manifest or campaign file writes them)."""
        p = super().params()
        for key in ("modes", "transition"):
            if p[key] is not None:
                p[key] = [list(row) for row in p[key]]
        return p

    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        m, N = state.model, self.n_particles
        if self._rates.shape[1] != m.nx:
            raise ReplayError(
                f"{self.owner()}: modes must have {m.nx} rates per mode (one per state "
                f"component of this model; got {self._rates.shape[1]})"
            )
        X = particles.gaussian(state.x[None], state.P[None], N, [state.rng])[0]
        state.particles = wrap_components(X, m.x_angles)
        state.modes = state.rng.integers(0, len(self._rates), N)
        state.w = np.full(N, 1.0 / N)
        state.mu_sum = np.zeros(len(self._rates))
        state.resampled, state.steps, state.ess_sum = 0, 0, 0.0

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
        state.w = particles.normalise(logw[None])[0][0]

    def estimate(self, state):
        w = state.w[None]
        x, P = particles.estimate(state.particles[None], w, state.model.x_angles)
        state.mu_sum += np.bincount(state.modes, weights=state.w, minlength=len(self._rates))
        state.ess_sum += float(particles.ess(w)[0])  # before resampling
        state.steps += 1
        idx = particles.resample(w, [state.rng], self.resampling, self.ess_threshold).get(0)
        if idx is not None:
            state.particles, state.modes = state.particles[idx], state.modes[idx]
            state.w = np.full(self.n_particles, 1.0 / self.n_particles)
            state.resampled += 1
        return x[0], P[0]

    def finish(self, state, info):
        info.update(
            resampled=state.resampled,
            mean_ess=state.ess_sum / max(state.steps, 1),
            mean_mode_probability=(state.mu_sum / max(state.steps, 1)).tolist(),
        )
