"""The swarm steps of paper 002, compiled (numba): the array passes of one PSO iteration
(:func:`scaled_uniforms`, :func:`pso_velocity`, :func:`pso_best`; :func:`replay.filters.p002.pso.optimize`
calls the fitness between them), the GWO leaders (:func:`leaders`) and the IGWO leader weights
(:func:`entropy_weights`, 002 §3.2.2)."""

from __future__ import annotations

import math

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np


@nb.njit(cache=True)
def scaled_uniforms(raw, scales, out):
    """out[t, c, j] = (raw[t, c, j] + 0.5) 2^-32 scales[t, c]: 32-bit integers to uniforms in (0, 1)
    (:func:`replay.filters.p002.gwo.uniforms`), times a coefficient per iteration t and kind c."""
    for t in range(raw.shape[0]):
        for c in range(raw.shape[1]):
            s = scales[t, c]
            for j in range(raw.shape[2]):
                out[t, c, j] = ((raw[t, c, j] + 0.5) * 2.0**-32) * s


@nb.njit(cache=True)
def pso_velocity(V, X, pbest, g, R, it, w, keep):
    """One PSO move of every particle in place (002 §4.1): V = w V + c1 r1 (pbest - X) + c2 r2 (g - X),
    times ``keep`` (M, d) (None: all components move), then X = X + V. ``R[m, it, 0]`` holds
    c1 r1, ``R[m, it, 1]`` c2 r2; ``g`` (M,) the index of each swarm's best. Sums in that order."""
    M, N, d = X.shape
    for m in range(M):
        b = g[m]
        for i in range(N):
            for q in range(d):
                x = X[m, i, q]
                v = V[m, i, q] * w
                v = v + (pbest[m, i, q] - x) * R[m, it, 0, i, q]
                v = v + (pbest[m, b, q] - x) * R[m, it, 1, i, q]
                if keep is not None:
                    v = v * keep[m, q]
                V[m, i, q] = v
                X[m, i, q] = x + v


@nb.njit(cache=True)
def pso_best(X, f, pbest, pf, g, best):
    """The personal bests (pbest, pf) of the positions X with fitness f (where f < pf), each swarm's
    best index g (``np.argmin``: the first minimum, or the first NaN) and its fitness into ``best`` (M,)."""
    M, N, d = X.shape
    for m in range(M):
        for i in range(N):
            if f[m, i] < pf[m, i]:
                pf[m, i] = f[m, i]
                for q in range(d):
                    pbest[m, i, q] = X[m, i, q]
        k, lo = 0, pf[m, 0]
        if not np.isnan(lo):
            for i in range(1, N):
                if not pf[m, i] >= lo:
                    k, lo = i, pf[m, i]
                    if np.isnan(lo):
                        break
        g[m] = k
        best[m] = lo


@nb.njit(cache=True)
def leaders(f, k, out):
    """Indices of the k smallest of ``f`` in increasing order (ties: lower index first): alpha, beta, delta."""
    for j in range(k):
        best = -1
        for i in range(f.shape[0]):
            taken = False
            for q in range(j):
                if out[q] == i:
                    taken = True
            if taken:
                continue
            if best < 0 or f[i] < f[best]:
                best = i
        out[j] = best


@nb.njit(cache=True)
def entropy_weights(fl, eps, xi, w):
    """IGWO entropy weights (002 §3.2.2) of the leaders' fitness ``fl`` (k,) into ``w`` (k,):
    p_i = (1 / (f_i + eps)) / sum_j 1 / (f_j + eps), E_i = -p_i log(p_i + eps),
    w_i = max(1 - E_i, xi), normalised to sum one.

    Not monotone in the fitness: E = -p log p peaks at p = 1/e, so a leader whose share p
    is near 1/e gets the smallest weight, e.g. f = [1, 1.5, 10] -> w = [0.316, 0.294, 0.390]
    (the worst leader weighs most; docs/reproduction/002.md, tests/test_paper002.py)."""
    k = fl.shape[0]
    sinv = 0.0
    for j in range(k):
        sinv += 1.0 / (fl[j] + eps)
    sw = 0.0
    for j in range(k):
        p = (1.0 / (fl[j] + eps)) / sinv
        w[j] = max(1.0 + p * math.log(p + eps), xi)
        sw += w[j]
    for j in range(k):
        w[j] /= sw
