"""Compiled (numba) small linear algebra and angle helpers: one source for every compiled step.

Written as plain loops over small matrices (3x3 to 20x20): at these sizes a
loop beats a BLAS/LAPACK call, whose fixed cost (about 1 µs) is most of the work.
Each function's un-jitted ``py_func`` is the same arithmetic in Python (tests
compare them). Used by the Kalman-family correction (:func:`kalman_correct`,
:func:`gain_nis`, wrapped in :mod:`replay.filters.kalman` and
:mod:`replay.filters.sigma`) and by paper 002's kernels
(:mod:`replay.filters.p002.compiled_util` re-exports them).

Stacks: :func:`gain_nis` and :func:`kalman_correct` take a leading Monte Carlo
run axis and treat each run alone with the same loops, so a run's numbers do
not depend on the other runs of its stack (one run is a stack of one).
"""
from __future__ import annotations

import numba as nb
import numpy as np

TWO_PI = 2.0 * np.pi


@nb.njit(cache=True)
def wrap(v, mask):
    """Wrap the ``mask`` components of ``v`` into [-pi, pi) in place (the arithmetic of replay.util.angles.wrap)."""
    for i in range(v.shape[0]):
        if mask[i]:
            v[i] -= np.floor(v[i] * (1.0 / TWO_PI) + 0.5) * TWO_PI


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
def gain_nis(S, Pxz, y, K, nis):
    """For each run m of the stacks S (M, nz, nz), Pxz (M, nx, nz), y (M, nz): the gain
    K[m] = Pxz[m] S[m]^-1 and nis[m] = y[m]' S[m]^-1 y[m] (Bar-Shalom et al. 2001, eq. 5.2.3-14
    and §5.4.2). Returns the first run whose S is not positive definite (its K and the later
    runs' are not computed), or -1."""
    M, nx, nz = Pxz.shape
    L = np.empty((nz, nz))
    for m in range(M):
        if not cholesky(S[m], L):
            return m
        solve_rows(L, Pxz[m], K[m])
        nis[m] = whitened_norm2(L, y[m])
    return -1


@nb.njit(cache=True)
def kalman_correct(x, P, y, S, Pxz, xmask, nis):
    """The Kalman correction with a cross-covariance, in place on each run m of the stacks
    x (M, nx), P (M, nx, nx) (sigma-point filters, Wan & van der Merwe 2000, eq. 15-17):

        K = Pxz S^-1,   x = x + K y   (``xmask`` components wrapped),
        P = P - K Pxz'  (= P - K S K'), then symmetrised: P = (P + P') / 2,
        nis = y' S^-1 y.

    Returns the first run whose S is not positive definite (that run and the later ones are
    left as they were), or -1."""
    M, nx, nz = Pxz.shape
    L = np.empty((nz, nz))
    K = np.empty((nx, nz))
    for m in range(M):
        if not cholesky(S[m], L):
            return m
        solve_rows(L, Pxz[m], K)
        nis[m] = whitened_norm2(L, y[m])
        for i in range(nx):
            t = 0.0
            for j in range(nz):
                t += K[i, j] * y[m, j]
            x[m, i] += t
        wrap(x[m], xmask)
        for i in range(nx):
            for j in range(nx):
                t = 0.0
                for q in range(nz):
                    t += K[i, q] * Pxz[m, j, q]
                P[m, i, j] -= t
        for i in range(nx):
            for j in range(i):
                t = 0.5 * (P[m, i, j] + P[m, j, i])
                P[m, i, j] = t
                P[m, j, i] = t
    return -1


@nb.njit(cache=True)
def sigma_points(x, P, xi, X, dev):
    """Sigma points of each run m of the stacks x (M, n), P (M, n, n): dev[m] = xi L' (the
    deviations L xi_i of the unit points xi (p, n), L the lower Cholesky factor of P[m]) and
    X[m] = x[m] + dev[m]. Returns the first run whose P is not positive definite, or -1."""
    M, n = x.shape
    L = np.empty((n, n))
    for m in range(M):
        if not cholesky(P[m], L):
            return m
        for i in range(xi.shape[0]):
            for j in range(n):
                t = 0.0
                for q in range(j + 1):  # L lower triangular
                    t += xi[i, q] * L[j, q]
                dev[m, i, j] = t
                X[m, i, j] = x[m, j] + t
    return -1
