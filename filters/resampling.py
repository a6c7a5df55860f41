"""Resampling schemes: each maps normalised weights ``w`` (N,) of one run to ancestor indices.

:func:`replay.filters.particles.resample` applies them over the run axis (and
``particles.ess`` is the effective sample size that decides when).

Both invert the cumulative weights c_j = w_1 + ... + w_j (c_N set to 1, a guard
against round-off leaving the last positions unmatched) at positions u: the
ancestor of position u is the first j with c_j > u.
"""

from __future__ import annotations

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np


@nb.njit(cache=True)
def invert_sorted(w, u0, out):
    """Ancestors ``out`` (n,) of the evenly spaced positions u_i = (u0 + i) / n, in one merge over
    the running sums of w (the sums of ``numpy.cumsum``, so the same indices as
    ``searchsorted(cumsum(w), u, side="right")`` with the guard)."""
    N, n = w.shape[0], out.shape[0]
    j, s = 0, w[0]
    c = s if N > 1 else 1.0
    for i in range(n):
        u = (u0 + i) / n
        while c <= u and j < N - 1:
            j += 1
            s += w[j]
            c = s if j < N - 1 else 1.0
        out[i] = j


def systematic(w: np.ndarray, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """Systematic resampling (Kitagawa 1996): one uniform u0, n evenly spaced positions (u0 + i) / n."""
    out = np.empty(len(w) if n is None else n, dtype=np.int64)
    invert_sorted(w, rng.random(), out)
    return out


def multinomial(w: np.ndarray, rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    """Multinomial resampling: n independent uniform positions."""
    n = len(w) if n is None else n
    c = np.cumsum(w)
    c[-1] = 1.0
    return np.searchsorted(c, rng.random(n), side="right")


SCHEMES = {"systematic": systematic, "multinomial": multinomial}
