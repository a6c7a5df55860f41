"""Particle bookkeeping shared by every particle filter, over the leading run axis.

Arrays: particles ``X`` (M, N, nx), log-weights ``logw`` (M, N), normalised
weights ``w`` (M, N), for M Monte Carlo runs of N particles each. Every
function acts on each run's row alone (reductions along the particle axis,
stacked matrix products, one generator per run), so run m's numbers do not
depend on the other runs in the stack: M runs at once equal M runs of one,
bit for bit.

    normalise   w^i = exp(l^i - max_j l^j) / sum_j exp(l^j - max_j l^j)          (log domain)
                log w^i = l^i - max_j l^j - log sum_j exp(l^j - max_j l^j)
    estimate    x = sum_i w^i x^i,  angle components: atan2(sum w^i sin x^i, sum w^i cos x^i)
                P = sum_i w^i (x^i - x)(x^i - x)'      (angle residuals wrapped to [-pi, pi))
    ess         ESS = 1 / sum_i (w^i)^2                  (Kong, Liu & Wong 1994; N for uniform weights)
    resample    ancestors a^i ~ w, only for runs with ESS < threshold * N
                (threshold = 1: every step; 0: never)
    roughen     x^i_j += K E_j N^(-1/d) e^i_j,  e ~ N(0, 1),  E_j = max_i x^i_j - min_i x^i_j
                (Gordon, Salmond & Smith 1993, §4; d = nx)
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import index, wrap

from .resampling import SCHEMES


def normalise(logw: np.ndarray):
    """Normalised weights and log-weights ``(w, logw)`` (M, N) of unnormalised log-weights (M, N)."""
    a = logw - logw.max(axis=-1, keepdims=True)
    w = np.exp(a)
    s = w.sum(axis=-1, keepdims=True)
    w /= s
    a -= np.log(s)
    return w, a


def estimate(X: np.ndarray, w: np.ndarray, angles=()):
    """Weighted mean ``x`` (M, nx) and covariance ``P`` (M, nx, nx) of particles X (M, N, nx).

    Angle components (``angles``, indices along the last axis) get the circular
    mean and wrapped residuals. (Elementwise work runs on (M N, nx) views:
    numpy costs less on 2-d arrays than on 3-d ones.)
    """
    M, N, nx = X.shape
    wr = w[:, None, :]  # (M, 1, N): one stacked product per run
    x = (wr @ X)[:, 0]
    if angles:
        i = index(tuple(angles))
        Xa = X.reshape(M * N, nx)[:, i]
        sin, cos = np.sin(Xa).reshape(M, N, -1), np.cos(Xa).reshape(M, N, -1)
        x[:, i] = np.arctan2((wr @ sin)[:, 0], (wr @ cos)[:, 0])
    D = X - x[:, None, :]
    if angles:  # particles' angles are not kept wrapped: wrap every residual (no test first)
        D2 = D.reshape(M * N, nx)
        D2[:, i] = wrap(D2[:, i])
    P = (D.swapaxes(-1, -2) * wr) @ D
    return x, P


def ess(w: np.ndarray) -> np.ndarray:
    """Effective sample size 1 / sum w^2 of each run (M,)."""
    return 1.0 / (w[:, None, :] @ w[:, :, None])[:, 0, 0]


def resample(w: np.ndarray, rngs, scheme: str = "systematic", threshold: float = 1.0) -> dict:
    """Ancestor indices (N,) for each run j (row of ``w``) whose ESS < threshold * N.

    Returns ``{j: indices}``; run j draws from ``rngs[j]`` only. Runs above the
    threshold are absent (not resampled, nothing drawn from their generator).
    """
    draw, limit = SCHEMES[scheme], threshold * w.shape[-1]
    return {j: draw(w[j], rngs[j]) for j, e in enumerate(ess(w).tolist()) if e < limit}


def roughen(X_j: np.ndarray, K: float, rng: np.random.Generator) -> np.ndarray:
    """One run's resampled particles (N, nx) with roughening jitter of sd K E_j N^(-1/nx)."""
    N, nx = X_j.shape
    sd = K * np.ptp(X_j, axis=0) * N ** (-1.0 / nx)
    return X_j + rng.standard_normal(X_j.shape) * sd


def gaussian(X0: np.ndarray, P0: np.ndarray, N: int, rngs) -> np.ndarray:
    """Initial particles (M, N, nx): x0_m + L_m e, e ~ N(0, I) from ``rngs[m]``, L_m L_m' = P0_m."""
    M, nx = X0.shape
    X = np.empty((M, N, nx))
    for m in range(M):
        L = np.linalg.cholesky(P0[m])
        X[m] = X0[m] + rngs[m].standard_normal((N, nx)) @ L.T
    return X
