"""Compiled (numba) small linear algebra, angle and weighted-moment helpers: the leaves of every
compiled step.

Written as plain loops over small matrices (3x3 to 20x20): at these sizes a
loop beats a BLAS/LAPACK call, whose fixed cost (about 1 µs) is most of the work.
Each function's un-jitted ``py_func`` is the same arithmetic in Python, the
readable reference (tests run it with ``tests/pure.py`` and compare bits).
Sums run in index order (no reassociation: numba compiles without fastmath),
and the transcendental functions are :mod:`math`'s, which numba compiles to the
same C library calls Python makes, so compiled and Python results are equal.
The Kalman-family steps built on them are :mod:`replay.filters.kalman_kernels`;
paper 002's kernels use them through :mod:`replay.filters.p002.compiled_util`;
the particle bookkeeping is :mod:`replay.filters.particles`.
"""

from __future__ import annotations

import math

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np

from replay.util import angles

LOG_2PI = math.log(2.0 * math.pi)
wrap_angle = nb.njit(cache=True)(angles.wrap)  # the one text of the angle wrap, compiled (of a number here)


@nb.njit(cache=True)
def wrap(v, mask):
    """Wrap the ``mask`` components of ``v`` into [-pi, pi) in place (:data:`wrap_angle` of each)."""
    for i in range(v.shape[0]):
        if mask[i]:
            v[i] = wrap_angle(v[i])


@nb.njit(cache=True)
def cholesky(A, L):
    """Lower Cholesky factor of A into L; False when A is not (numerically) positive definite."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        d = np.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / d
        for i in range(j):
            L[i, j] = 0.0
    return True


@nb.njit(cache=True)
def solve_rows(L, B, out):
    """out = B S^-1, S = L L' (L lower Cholesky factor (m, m)), B (n, m): each row b of B
    solves S x = b by forward then backward substitution (S symmetric: x' = b' S^-1)."""
    m = L.shape[0]
    y = np.empty(m)
    for r in range(B.shape[0]):
        for i in range(m):
            t = B[r, i]
            for k in range(i):
                t -= L[i, k] * y[k]
            y[i] = t / L[i, i]
        for i in range(m - 1, -1, -1):
            t = y[i]
            for k in range(i + 1, m):
                t -= L[k, i] * out[r, k]
            out[r, i] = t / L[i, i]


@nb.njit(cache=True)
def chol_solve_rows(S, B, out):
    """out = B S^-1 for symmetric positive-definite S (m, m) and B (n, m); False when S is not."""
    m = S.shape[0]
    L = np.empty((m, m))
    if not cholesky(S, L):
        out[:, :] = np.nan
        return False
    solve_rows(L, B, out)
    return True


@nb.njit(cache=True)
def whitened_norm2(L, y):
    """y' S^-1 y = |L^-1 y|^2 for S = L L' (forward substitution)."""
    m = L.shape[0]
    v = np.empty(m)
    s = 0.0
    for i in range(m):
        t = y[i]
        for k in range(i):
            t -= L[i, k] * v[k]
        v[i] = t / L[i, i]
        s += v[i] * v[i]
    return s


@nb.njit(cache=True)
def matmul(A, B, out):
    """out = A B by loops (BLAS calls cost more than these small products)."""
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            t = 0.0
            for k in range(A.shape[1]):
                t += A[i, k] * B[k, j]
            out[i, j] = t


@nb.njit(cache=True)
def quad(d, W):
    """d' W d."""
    s = 0.0
    for i in range(d.shape[0]):
        t = 0.0
        for j in range(d.shape[0]):
            t += W[i, j] * d[j]
        s += d[i] * t
    return s


@nb.njit(cache=True)
def gauss_logpdf(maha, const):
    """The Gaussian log-density -(maha + const) / 2 of a residual d with Mahalanobis term
    maha = d' C^-1 d and const = log det C + dim log 2 pi (:data:`LOG_2PI`): the project's one
    text of it (numbers or arrays alike). A caller that adds log det C to maha first passes
    (maha + log det C, dim log 2 pi): the order its numbers were computed in (paper 002's kernels);
    one whose constants cancel passes what is left (a log-ratio of densities)."""
    return -0.5 * (maha + const)


@nb.njit(cache=True)
def gauss_loglik(zh, z, zmask, diagonal, L, inv_var, const, out):
    """Gaussian log-likelihoods out[i] = -0.5 (d_i' R^-1 d_i + c) of the rows zh (P, nz)
    (predicted measurements), d_i = z - zh[i] with the ``zmask`` components wrapped; ``const``
    = c = log det R + nz log 2 pi. R is given by its inverse variances ``inv_var`` (nz,) when
    ``diagonal``, else by its lower Cholesky factor ``L`` (d' R^-1 d = |L^-1 d|^2)."""
    P, nz = zh.shape
    d = np.empty(nz)
    for i in range(P):
        for j in range(nz):
            d[j] = z[j] - zh[i, j]
        wrap(d, zmask)
        if diagonal:
            s = 0.0
            for j in range(nz):
                s += d[j] * d[j] * inv_var[j]
        else:
            s = whitened_norm2(L, d)
        out[i] = gauss_logpdf(s, const)


@nb.njit(cache=True)
def point_mean(Y, w, mask, out):
    """out = sum_i w_i Y[i] of points Y (p, n), weights w (p,) (may be negative; sum one); the
    ``mask`` components get the circular mean atan2(sum w_i sin Y_i, sum w_i cos Y_i)."""
    p, n = Y.shape
    for q in range(n):
        if mask[q]:
            ss, cc = 0.0, 0.0
            for i in range(p):
                ss += w[i] * math.sin(Y[i, q])
                cc += w[i] * math.cos(Y[i, q])
            out[q] = math.atan2(ss, cc)
        else:
            t = 0.0
            for i in range(p):
                t += w[i] * Y[i, q]
            out[q] = t


@nb.njit(cache=True)
def deviations(Y, mean, mask, D):
    """D[i] = Y[i] - mean with the ``mask`` components wrapped to [-pi, pi)."""
    for i in range(Y.shape[0]):
        for q in range(Y.shape[1]):
            D[i, q] = Y[i, q] - mean[q]
        wrap(D[i], mask)


@nb.njit(cache=True)
def weighted_outer(A, B, w, out):
    """out = sum_i w_i A[i]' B[i] = A' diag(w) B for A (p, na), B (p, nb): the weighted
    cross-covariance of deviations (summed in point order)."""
    for a in range(A.shape[1]):
        for b in range(B.shape[1]):
            t = 0.0
            for i in range(A.shape[0]):
                t += (w[i] * A[i, a]) * B[i, b]
            out[a, b] = t


@nb.njit(cache=True)
def symmetrise(P):
    """P = (P + P') / 2 in place (each pair of off-diagonal entries set to their mean)."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i):
            t = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = t
            P[j, i] = t
