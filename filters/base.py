"""What every filter shares: the run loop, the estimates it returns, divergence.

A filter is configured by its constructor (its parameters, named and defaulted)
and run by :meth:`Filter.run` on a :class:`replay.model.Model` and an array of
measurements ``z`` of shape ``(n, nz)``; NaN components are missing (a row of
NaN means predict only; a partly NaN row updates with the finite components).

Time convention: ``x0, P0`` describe the state one step before the first
measurement; every step k = 0..n-1 predicts with ``f(., k)`` and then updates
with ``z[k]``. Estimates are the posterior mean and covariance at each step.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from time import perf_counter

import numpy as np


@dataclass
class Estimates:
    """Posterior means ``x`` (n, nx), covariances ``P`` (n, nx, nx), seconds per step."""

    x: np.ndarray
    P: np.ndarray
    step_seconds: np.ndarray
    diverged_at: int | None = None
    info: dict = field(default_factory=dict)

    @property
    def diverged(self) -> bool:
        return self.diverged_at is not None

    @property
    def us_per_step(self) -> float:
        s = self.step_seconds[np.isfinite(self.step_seconds)]
        return float(np.median(s) * 1e6) if len(s) else float("nan")


class State:
    """Mutable per-run filter state (mean, covariance, particles, rng, ...)."""

    def __init__(self, model, rng):
        self.model = model
        self.rng = rng


class Filter:
    """Base class. Subclasses define ``start``, ``predict``, ``update``, ``estimate``."""

    name = "filter"

    def start(self, state: State, x0: np.ndarray, P0: np.ndarray) -> None:
        state.x = np.array(x0, dtype=float)
        state.P = np.array(P0, dtype=float)

    def predict(self, state: State, k: int) -> None:
        raise NotImplementedError

    def update(self, state: State, z: np.ndarray, k: int, mask) -> None:
        raise NotImplementedError

    def estimate(self, state: State):
        return state.x, state.P

    def finish(self, state: State, info: dict) -> None:
        """Add run diagnostics to ``info`` (e.g. resampling counts)."""

    def params(self) -> dict:
        """The filter's parameters, for manifests and leaderboards."""
        return {k: v for k, v in vars(self).items() if not k.startswith("_")}

    def run(self, model, z, x0, P0, rng: np.random.Generator | None = None) -> Estimates:
        z = np.asarray(z, dtype=float)
        n, nx = len(z), model.nx
        state = State(model, rng if rng is not None else np.random.default_rng(0))
        self.start(state, x0, P0)
        X = np.full((n, nx), np.nan)
        P = np.full((n, nx, nx), np.nan)
        secs = np.full(n, np.nan)
        finite = np.isfinite(z)
        full, some = finite.all(axis=1), finite.any(axis=1)
        diverged = None
        clock = perf_counter
        for k in range(n):
            t0 = clock()
            try:
                self.predict(state, k)
                if full[k]:
                    self.update(state, z[k], k, None)
                elif some[k]:
                    self.update(state, z[k], k, finite[k])
                X[k], P[k] = self.estimate(state)
            except (np.linalg.LinAlgError, FloatingPointError):
                diverged = k
                break
            secs[k] = clock() - t0
        # Divergence: the first step whose estimate is non-finite or whose covariance has a
        # negative variance (checked once over the arrays, not on every step's hot path).
        end = n if diverged is None else diverged
        ok = (np.isfinite(X[:end]).all(axis=1) & np.isfinite(P[:end]).all(axis=(1, 2))
              & (np.diagonal(P[:end], axis1=1, axis2=2) >= 0.0).all(axis=1))
        if not ok.all():
            diverged = int(np.argmin(ok))
        if diverged is not None:
            X[diverged:], P[diverged:], secs[diverged:] = np.nan, np.nan, np.nan
        info = {}
        self.finish(state, info)
        return Estimates(X, P, secs, diverged, info)
