"""Resampling schemes: each maps normalised weights ``w`` (N,) of one run to ancestor indices.

:func:`replay.filters.particles.resample` applies them over the run axis (and
``particles.ess`` is the effective sample size that decides when).
"""
from __future__ import annotations

import numpy as np


def systematic(w: np.ndarray, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """Systematic resampling (Kitagawa 1996): one uniform, N evenly spaced positions."""
    n = len(w) if n is None else n
    u = (rng.random() + np.arange(n)) / n
    c = np.cumsum(w)
    c[-1] = 1.0  # guard against round-off leaving the last positions unmatched
    return np.searchsorted(c, u, side="right")


def multinomial(w: np.ndarray, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """Multinomial resampling: N independent draws from the weights."""
    n = len(w) if n is None else n
    c = np.cumsum(w)
    c[-1] = 1.0
    return np.searchsorted(c, rng.random(n), side="right")


SCHEMES = {"systematic": systematic, "multinomial": multinomial}
