"""Weight-factor particle filter (paper 003, §3, eq. 22–27).

The bootstrap PF of :mod:`replay.filters.pf` (over the Monte Carlo run axis,
without roughening) with two changes from 003, made in its weighting step:

* likelihood weights are floored at ``weight_floor`` = 1e−99 (§2, under
  eq. 22: "to avoid zero weights, the minimum is set to 1e−99"): applied to
  the unnormalised weight w_{k−1} p(z_k | x_k), in the log domain;
* after normalisation each weight is raised to the power α (eq. 27),

      w_new^i = (w^i)^α / Σ_j (w^j)^α,   0 < α ≤ 1,

  which lifts small weights and lowers large ones before resampling (the
  paper's eq. 28–32), keeping more distinct particles (less impoverishment).
  α = 1 is the standard PF (with the floor; bit for bit the bootstrap PF
  wherever the floor does not bind: tested); α → 0 gives uniform weights.

With resampling at every step (``ess_threshold`` = 1, the paper's) the
weights before eq. 27 are the normalised likelihoods, so the WF-PF weighs by
p(z | x)^α: a PF with a flattened likelihood — for a Gaussian N(h(x), R),
exactly the PF with R/α (tests/test_wfpf.py). With the exact likelihood the
exponent is a mis-specification; docs/reproduction/003.md measures where, if
anywhere, it helps.

The paper prints 0.75 for an "influence factor" in both of its experiments;
in §4.2 it is this α (our ``alpha``, default 0.75). The glint strength ε of
eq. 7, also printed as 0.75 (§4.1), is a parameter of the noise model
(:class:`replay.models.noise.Glint`), not of this filter.

Where the exponent applies: the paper applies eq. 27 "in the normalisation
of the weights", before resampling, and estimates with eq. 25 after it. We
take the estimate from the tempered weights (the weights the resampler
sees), so the estimate and the resampled cloud agree.

Diagnostic (the paper's mechanism, eq. 28–32: fewer copies of the heavy
particles): the engine records per run and step the number of distinct
particles after the resampling step (``info["distinct"]``, (n,) of the run's
steps; :meth:`replay.filters.base.Filter.run` and ``Evaluation.results[i].
estimates[r].info``; per run over the steps: :func:`mean_distinct`). Counting
draws nothing and changes no number.
"""

from __future__ import annotations

import numpy as np

from replay.filters.case import Case
from replay.util.params import Param

from .. import particles
from ..pf import ParticleFilter, PFEngine

_PF = {p.name: p for p in ParticleFilter.PARAMS}


class WeightFactorPF(ParticleFilter):
    """Bootstrap PF with weight floor and weight exponent α (003 eq. 22, 27)."""

    name = "wf-pf"
    CASE = Case(params={"n_particles": 150, "alpha": 0.5})
    PARAMS = (
        _PF["n_particles"],
        Param(
            "alpha",
            float,
            0.75,
            "weight exponent α of eq. 27 (1: the bootstrap PF; toward 0: uniform)",
            low=0.0,
            high=1.0,
            low_open=True,
        ),
        Param(
            "weight_floor",
            float,
            1e-99,
            "floor of the unnormalised weight w p(z | x) (§2, under eq. 22)",
            low=0.0,
            low_open=True,
        ),
        _PF["resampling"],
        _PF["ess_threshold"],
    )
    roughening = 0.0  # the paper has none

    def engine(self, model, rngs):
        return CountingEngine(self, model, rngs)

    def weigh(self, logw, ll):
        l = np.maximum(logw + ll, np.log(self.weight_floor))  # floor 1e-99 (eq. 22)
        w, l = particles.normalise(l)  # normalised (eq. 23)
        if self.alpha == 1.0:  # eq. 27 is the identity: skip it, so that alpha = 1 is the PF bit for bit
            return w, l
        return temper(l, self.alpha)  # eq. 27


def temper(logw: np.ndarray, alpha: float):
    """Eq. 27 on normalised log-weights (..., N): (w, log w) of w^α / Σ w^α."""
    return particles.normalise(alpha * logw)


def distinct(X_j: np.ndarray) -> int:
    """Distinct particles of one run's cloud (N, nx): copies made by resampling share every
    component, and continuous process noise never makes two equal, so the first component suffices."""
    return int(np.unique(X_j[:, 0]).size)


def mean_distinct(estimates) -> np.ndarray:
    """Per run: the mean over steps of the distinct particles after resampling (``info["distinct"]`` of each
    run's estimates, as :class:`CountingEngine` records them; NaN for a run without the record)."""
    return np.array([np.mean(getattr(e, "info", {}).get("distinct", np.nan)) for e in estimates])


class CountingEngine(PFEngine):
    """The PF engine, recording the distinct particles after each resampling step of each run."""

    def start(self, X0, P0):
        super().start(X0, P0)
        self.distinct = [[] for _ in range(len(X0))]

    def resample(self):
        super().resample()
        for j, m in enumerate(self.ids):
            self.distinct[m].append(distinct(self.X[j]))

    def finish(self, m, info):
        super().finish(m, info)
        info["distinct"] = np.array(self.distinct[m], int)
