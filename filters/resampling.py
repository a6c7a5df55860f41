"""Resampling schemes: each maps normalised weights ``w`` (N,) to ancestor indices."""
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


def effective_sample_size(w: np.ndarray) -> float:
    """ESS = 1 / sum w_i^2 for normalised weights."""
    return 1.0 / float(w @ w)


SCHEMES = {"systematic": systematic, "multinomial": multinomial}
