"""Particle bookkeeping shared by every particle filter, over the leading run axis: one source.

Arrays: particles ``X`` (M, N, nx), log-weights ``logw`` (M, N), normalised
weights ``w`` (M, N), for M Monte Carlo runs of N particles each. Every
function acts on each run's row alone (one loop per run, reductions in
particle order, one generator per run), so run m's numbers do not depend on
the other runs in the stack: M runs at once equal M runs of one, bit for bit.

    normalise   w^i = exp(l^i - max_j l^j) / sum_j exp(l^j - max_j l^j)          (log domain)
                log w^i = l^i - max_j l^j - log sum_j exp(l^j - max_j l^j)
    estimate    x = sum_i w^i x^i,  angle components: atan2(sum w^i sin x^i, sum w^i cos x^i)
                P = sum_i w^i (x^i - x)(x^i - x)'      (angle residuals wrapped to [-pi, pi))
    ess         ESS = 1 / sum_i (w^i)^2                  (Kong, Liu & Wong 1994; N for uniform weights)
    resample    ancestors a^i ~ w, only for runs with ESS < threshold * N
                (threshold = 1: every step; 0: never)
    roughen     x^i_j += K E_j N^(-1/d) e^i_j,  e ~ N(0, 1),  E_j = max_i x^i_j - min_i x^i_j
                (Gordon, Salmond & Smith 1993, §4; d = nx)

The arithmetic is written once, as numba kernels (``*_rows``, :func:`weights`,
:func:`moments`, :func:`perturb`, :func:`roughen`; the weighted mean is
:func:`replay.util.kernels.point_mean`): plain loops, sums taken in particle order. Their un-jitted
``py_func`` is the same code run by Python: the readable reference, equal to
the compiled kernels bit for bit (``tests/test_particles.py``). The Python
functions below (:func:`normalise`, :func:`estimate`, :func:`ess`,
:func:`resample`, ...) are thin wrappers that allocate the outputs. Paper
002's compiled kernels call the same kernels (re-exported by
:mod:`replay.filters.p002.compiled_util`).
"""

from __future__ import annotations

import math

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np

from replay.util.angles import angle_mask
from replay.util.kernels import point_mean as weighted_mean  # the w-weighted (circular) mean of rows
from replay.util.kernels import LOG_2PI, wrap, wrap_angle

from .resampling import SCHEMES


# --- the kernels (one run each, or a stack of runs) ---------------------------------------
@nb.njit(cache=True)
def weights(lw, w):
    """One run: weights w (N,) proportional to exp(lw), summing to one; lw renormalised in place
    to log w (the log-domain normalisation of the module docstring)."""
    top = lw.max()
    tot = 0.0
    for i in range(lw.shape[0]):
        w[i] = math.exp(lw[i] - top)
        tot += w[i]
    lt = math.log(tot)
    for i in range(lw.shape[0]):
        lw[i] = lw[i] - top - lt
        w[i] /= tot


@nb.njit(cache=True)
def moments(X, w, xang, x, P):
    """One run: weighted (circular) mean x (n,) of particles X (N, n) and covariance P (n, n)
    of the deviations, angle deviations wrapped."""
    N, n = X.shape
    d = np.empty(n)
    weighted_mean(X, w, xang, x)
    for a in range(n):
        for b in range(n):
            P[a, b] = 0.0
    for i in range(N):
        for q in range(n):
            d[q] = X[i, q] - x[q]
        wrap(d, xang)
        for a in range(n):
            for b in range(a + 1):
                P[a, b] += w[i] * d[a] * d[b]
    for a in range(n):
        for b in range(a):
            P[b, a] = P[a, b]


@nb.njit(cache=True, nogil=True)
def normalise_rows(logw, w):
    """Every run m: :func:`weights` of logw[m] into w[m] (logw renormalised in place)."""
    for m in range(logw.shape[0]):
        weights(logw[m], w[m])


@nb.njit(cache=True, nogil=True)
def moments_rows(X, w, xang, x, P):
    """Every run m: :func:`moments` of X[m] (N, n) with weights w[m] into x[m], P[m]."""
    for m in range(X.shape[0]):
        moments(X[m], w[m], xang, x[m], P[m])


@nb.njit(cache=True)
def ess_rows(w, out):
    """Every run m: ESS = 1 / sum_i w[m, i]^2 into out[m] (one run: a (1, N) view)."""
    for m in range(w.shape[0]):
        s = 0.0
        for i in range(w.shape[1]):
            s += w[m, i] * w[m, i]
        out[m] = 1.0 / s


@nb.njit(cache=True)
def perturb(X, sd, g):
    """One run: X[i, q] += e sd[q] in place, e ~ N(0, 1) drawn from the generator ``g`` particle by
    particle, component by component (the order of ``g.standard_normal(X.shape)``): the Gaussian
    noise of the propagation (sd the standard deviations of a diagonal Q) and of :func:`roughen`."""
    for i in range(X.shape[0]):
        for q in range(X.shape[1]):
            X[i, q] += g.standard_normal() * sd[q]


@nb.njit(cache=True)
def roughen(X, K, g):
    """One run's resampled particles X (N, n), roughened in place (module docstring): the jitter of
    sd K E_q N^(-1/n), E_q = max_i X[i, q] - min_i X[i, q], drawn from ``g`` (:func:`perturb`).
    Returns X."""
    N, n = X.shape
    shrink = N ** (-1.0 / n)
    sd = np.empty(n)
    for q in range(n):
        lo, hi = X[0, q], X[0, q]
        for i in range(1, N):
            lo, hi = min(lo, X[i, q]), max(hi, X[i, q])
        sd[q] = K * (hi - lo) * shrink
    perturb(X, sd, g)
    return X


@nb.njit(cache=True)
def propose(Y, sd, z, sel, idx, sgn, rvar, zmask, ll, g):
    """One run's locally optimal proposal (Doucet, Godsill & Andrieu 2000, §II.D) for a
    measurement that selects state components, ``h(x) = sgn * x[idx]`` with diagonal Q and R:
    particles Y (N, n) = f(x^i) are moved in place to a draw of p(x_k | x^i_{k-1}, z_k) and
    ``ll`` (N,) gets the predictive log-likelihoods log p(z_k | x^i_{k-1}) (the weight factor).

    Per particle, from prior mean f(x^i) and variances sd^2, for each measured component j
    (``sel = [d, j_0 .. j_{d-1}]``; s = idx[j], a = sgn[j]) in turn (a sequential Kalman update,
    exact for a diagonal R, several components of one state included)::

        S = a^2 v_s + R_j,  r = z_j - a m_s (wrapped: ``zmask``),  ll += log N(r; 0, S)
        m_s += v_s a r / S,  v_s -= v_s^2 a^2 / S

    then x^i = m + sqrt(v) e, e ~ N(0, I) drawn from ``g`` particle by particle, component by
    component (:func:`perturb`'s order). No measured component (d = 0): :func:`perturb` itself,
    ``ll`` untouched."""
    d = sel[0]
    if d == 0:
        perturb(Y, sd, g)
        return
    N, n = Y.shape
    v = np.empty(n)
    for i in range(N):
        for q in range(n):
            v[q] = sd[q] * sd[q]
        s_ll = 0.0
        for c in range(d):
            j = sel[1 + c]
            s, a = idx[j], sgn[j]
            S = a * a * v[s] + rvar[j]
            r = z[j] - a * Y[i, s]
            if zmask[j]:
                r = wrap_angle(r)
            s_ll -= 0.5 * (r * r / S + math.log(S) + LOG_2PI)
            K = v[s] * a / S
            Y[i, s] += K * r
            v[s] -= K * a * v[s]
        ll[i] = s_ll
        for q in range(n):
            Y[i, q] += g.standard_normal() * math.sqrt(v[q])


# --- Python API: allocate, call the kernels ---------------------------------------------
def normalise(logw: np.ndarray):
    """Normalised weights and log-weights ``(w, logw)`` (M, N) of unnormalised log-weights (M, N)
    (new arrays; ``logw`` is not changed)."""
    a = np.array(logw, dtype=float, order="C")
    w = np.empty_like(a)
    normalise_rows(a.reshape(-1, a.shape[-1]), w.reshape(-1, a.shape[-1]))
    return w, a


def estimate(X: np.ndarray, w: np.ndarray, angles=()):
    """Weighted mean ``x`` (M, nx) and covariance ``P`` (M, nx, nx) of particles X (M, N, nx)
    with normalised weights w (M, N); angle components (``angles``, indices along the last
    axis) get the circular mean and wrapped residuals."""
    M, N, nx = X.shape
    x, P = np.empty((M, nx)), np.empty((M, nx, nx))
    moments_rows(
        np.ascontiguousarray(X, dtype=float), np.ascontiguousarray(w, dtype=float), angle_mask(tuple(angles), nx), x, P
    )
    return x, P


def ess(w: np.ndarray) -> np.ndarray:
    """Effective sample size 1 / sum w^2 of each run (M,)."""
    out = np.empty(len(w))
    ess_rows(np.ascontiguousarray(w, dtype=float), out)
    return out


def resample(w: np.ndarray, rngs, scheme: str = "systematic", threshold: float = 1.0) -> dict:
    """Ancestor indices (N,) for each run j (row of ``w``) whose ESS < threshold * N.

    Returns ``{j: indices}``; run j draws from ``rngs[j]`` only. Runs above the
    threshold are absent (not resampled, nothing drawn from their generator).
    """
    draw, limit = SCHEMES[scheme], threshold * w.shape[-1]
    return {j: draw(w[j], rngs[j]) for j, e in enumerate(ess(w).tolist()) if e < limit}


def gaussian(X0: np.ndarray, P0: np.ndarray, N: int, rngs) -> np.ndarray:
    """Initial particles (M, N, nx): x0_m + L_m e, e ~ N(0, I) from ``rngs[m]``, L_m L_m' = P0_m."""
    M, nx = X0.shape
    X = np.empty((M, N, nx))
    for m in range(M):
        L = np.linalg.cholesky(P0[m])
        X[m] = X0[m] + rngs[m].standard_normal((N, nx)) @ L.T
    return X
