"""Model-free compiled (numba) helpers of paper 002's kernels: small linear algebra, angles, moments.

:mod:`replay.filters.p002.compiled` (the kernels that call a model's ``f``,
``h``, ``F``, ``H``) imports these; they are usable directly too (the particle
estimate :func:`estimate` needs no model). The particle bookkeeping is
:mod:`replay.filters.particles`' (imported); the repair of :func:`factor`
is that of the test oracle's ``batched_cholesky`` (``tests/oracle_p002.py``):

* :func:`wrap`, :func:`cholesky`, :func:`chol_solve_rows`, :func:`matmul`, :func:`quad` — from
  :mod:`replay.util.kernels` (the one compiled linear algebra of the project), re-exported;
* :func:`wrap_rows` (:func:`wrap` of every row of a stack: the numpy code's angle wrap);
* :func:`factor` (Cholesky with an eigenvalue-floor repair), :func:`gram`;
* :func:`cubature_points`, :func:`moments` — the cubature points and their
  equal-weight (circular) mean and deviations; :func:`sincos_small`;
* :func:`scaled_uniforms`, :func:`pso_velocity`, :func:`pso_best` — the array passes of one PSO
  iteration (:func:`replay.filters.p002.pso.optimize`, which calls the fitness between them);
* :func:`leaders` — the alpha, beta, delta wolves of GWO; :func:`entropy_weights` — the IGWO
  leader weights (002 §3.2.2; the kernel's only copy, callable from Python too);
* :func:`normalise`, :func:`weighted_mean` — the particle bookkeeping kernels of
  :mod:`replay.filters.particles` (log-domain normalisation, circular weighted mean),
  re-exported; :func:`estimate` composes them with the covariance over a stack of runs.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from replay.filters.particles import moments as particle_moments  # the one particle bookkeeping
from replay.filters.particles import weighted_mean  # noqa: F401 (re-exported)
from replay.filters.particles import weights as normalise
from replay.util.kernels import chol_solve_rows, cholesky, matmul, quad, wrap  # noqa: F401 (re-exported)

TWO_PI = 2.0 * np.pi
SIN_TAYLOR = tuple(1.0 / math.factorial(k) for k in (15, 13, 11, 9, 7, 5, 3))  # sin d = d - d^3 (1/3! - ...)
COS_TAYLOR = tuple(1.0 / math.factorial(k) for k in (16, 14, 12, 10, 8, 6, 4, 2))  # cos d = 1 - d^2 (1/2! - ...)


@nb.njit(cache=True)
def wrap_rows(X, mask):
    """:func:`wrap` of each row of X (rows, n) in place: the ``mask`` components into [-pi, pi).
    A row whose masked components are all below 3 < pi - 0.14 in size is left as it is: there
    floor(x / 2 pi + 0.5) = 0 exactly, so the wrap would give x itself (most rows, cheaper)."""
    for r in range(X.shape[0]):
        for i in range(X.shape[1]):
            if mask[i] and not abs(X[r, i]) < 3.0:
                wrap(X[r], mask)
                break


@nb.njit(cache=True)
def factor(A, L):
    """Cholesky factor of A into L, or of a repaired copy of A when needed: symmetrise, floor the
    eigenvalues at 1e-12 max(1, largest). A is not changed. Returns 1 when repaired, else 0."""
    if cholesky(A, L):
        return 0
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            if not np.isfinite(A[i, j]):
                L[:, :] = np.nan
                return 1
    S = 0.5 * (A + A.T)
    s, U = np.linalg.eigh(S)
    floor = 1e-12 * max(1.0, s.max())
    for i in range(n):
        s[i] = max(s[i], floor)
    if not cholesky((U * s) @ U.T, L):
        L[:, :] = np.nan
    return 1


@nb.njit(cache=True)
def sincos_small(d):
    """(sin d, cos d): Taylor polynomials for |d| <= 0.5 (truncation below 1e-19, i.e. exact to
    rounding), libm beyond. The cubature points of an angle lie close together, so their
    circular mean (about the first point) mostly needs small arguments: 7 + 8 multiply-adds
    instead of a libm sin and cos (the IGWO-STCPF step was 4-14 % faster in four alternating
    runs on the noisy 2-core machine)."""
    if abs(d) > 0.5:
        return np.sin(d), np.cos(d)
    d2 = d * d
    s = 0.0
    for a in SIN_TAYLOR:  # Horner in -d^2
        s = s * -d2 + a
    c = 0.0
    for a in COS_TAYLOR:
        c = c * -d2 + a
    return d - d * d2 * s, 1.0 - d2 * c


@nb.njit(cache=True)
def gram(D, out):
    """out = D' D / (rows of D): the lower triangle computed, the upper mirrored."""
    c, m = D.shape
    for a in range(m):
        for b in range(a + 1):
            t = 0.0
            for j in range(c):
                t += D[j, a] * D[j, b]
            out[a, b] = out[b, a] = t / c


@nb.njit(cache=True)
def cubature_points(x, L, s, pts):
    """The cubature points x +- s L e_j, j = 1..n, into pts (2n, n)."""
    n = x.shape[0]
    for j in range(n):
        for i in range(n):
            pts[j, i] = x[i] + s * L[i, j]
            pts[n + j, i] = x[i] - s * L[i, j]


@nb.njit(cache=True)
def moments(Y, mask, mean, D):
    """Equal-weight (circular for ``mask``) mean of the rows of Y (2n, m), and the wrapped deviations D."""
    c, m = Y.shape
    for i in range(m):
        if mask[i]:  # circular mean, about the first point: ref + atan2(sum sin d_j, sum cos d_j)
            ref = Y[0, i]
            ss, cc = 0.0, 0.0
            for j in range(c):
                d = Y[j, i] - ref
                d -= np.floor(d * (1.0 / TWO_PI) + 0.5) * TWO_PI
                sd, cd = sincos_small(d)
                ss += sd
                cc += cd
            t = ref + math.atan2(ss, cc)
            mean[i] = t - np.floor(t * (1.0 / TWO_PI) + 0.5) * TWO_PI
        else:
            t = 0.0
            for j in range(c):
                t += Y[j, i]
            mean[i] = t * (1.0 / c)
    for j in range(c):
        for i in range(m):
            D[j, i] = Y[j, i] - mean[i]
        wrap(D[j], mask)


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


@nb.njit(cache=True, nogil=True)
def estimate(X, logw, xang, x, P, w):
    """Weighted estimate of every run: the weights w (M, N) normalised from ``logw`` (which is
    renormalised in place), the weighted (circular) mean x (M, n) and covariance P (M, n, n)
    with wrapped deviations: the kernels of :mod:`replay.filters.particles`."""
    for m in range(X.shape[0]):
        normalise(logw[m], w[m])
        particle_moments(X[m], w[m], xang, x[m], P[m])
