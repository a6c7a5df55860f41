"""Weight-factor particle filter (paper 003, §3, eq. 22–27).

The bootstrap PF of :mod:`replay.filters.pf` with two changes from 003:

* likelihood weights are floored at ``weight_floor`` = 1e−99 (§2, under
  eq. 22: "to avoid zero weights, the minimum is set to 1e−99"): applied to
  the unnormalised weight w_{k−1} p(z_k | x_k), in the log domain;
* after normalisation each weight is raised to the power α (eq. 27),

      w_new^i = (w^i)^α / Σ_j (w^j)^α,   0 < α ≤ 1,

  which lifts small weights and lowers large ones before resampling (the
  paper's eq. 28–32), keeping more distinct particles (less impoverishment).
  α = 1 is the standard PF; α → 0 gives uniform weights.

The paper prints 0.75 for an "influence factor" in both of its experiments;
in §4.2 it is this α (our ``alpha``, default 0.75). The glint strength ε of
eq. 7, also printed as 0.75 (§4.1), is a parameter of the noise model
(:class:`replay.noise.Glint`), not of this filter.

Where the exponent applies: the paper applies eq. 27 "in the normalisation
of the weights", before resampling, and estimates with eq. 25 after it. We
take the estimate from the tempered weights (the weights the resampler
sees), so the estimate and the resampled cloud agree.
"""
from __future__ import annotations

import numpy as np

from replay.util.errors import ReplayError

from ..pf import ParticleFilter



class WeightFactorPF(ParticleFilter):
    """Bootstrap PF with weight floor and weight exponent α (003 eq. 27)."""

    name = "wf-pf"

    def __init__(self, n_particles: int = 1000, alpha: float = 0.75, weight_floor: float = 1e-99,
                 resampling: str = "systematic", ess_threshold: float = 1.0):
        super().__init__(n_particles, resampling, ess_threshold)
        a = float(alpha)
        if not 0.0 < a <= 1.0:
            raise ReplayError(f"wf-pf: weight exponent alpha={a:g} must lie in (0, 1]")
        if not float(weight_floor) > 0.0:
            raise ReplayError(f"wf-pf: weight_floor={weight_floor:g} must be positive")
        self.alpha = a
        self.weight_floor = float(weight_floor)

    def update(self, state, z, k, mask):
        logw = state.logw + state.model.loglik(z, state.particles, k, mask)
        logw = np.maximum(logw, np.log(self.weight_floor))  # floor 1e-99 (eq. 22)
        logw = logw - logw.max()
        logw -= np.log(np.exp(logw).sum())  # normalised (eq. 23)
        state.w, state.logw = temper(logw, self.alpha)


def temper(logw: np.ndarray, alpha: float):
    """Eq. 27 on normalised log-weights: (w, log w) of w^α / Σ w^α."""
    a = alpha * logw
    a -= a.max()
    w = np.exp(a)
    s = w.sum()
    return w / s, a - np.log(s)
