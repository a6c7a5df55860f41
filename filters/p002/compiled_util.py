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
* :func:`normalise`, :func:`weighted_mean` — the particle bookkeeping kernels of
  :mod:`replay.filters.particles` (log-domain normalisation, circular weighted mean),
  re-exported; :func:`estimate` composes them with the covariance over a stack of runs;
* :func:`fading_factor` (settings :class:`Fading`) — the STCKF's fading factor, the one kernel
  of :mod:`replay.filters.p002.stckf` and of the particles' STCKF proposal;
* :class:`Proposal`, :func:`workspace`, :func:`correct`, :func:`draw` — the settings, work arrays,
  Kalman correction and importance draw of :func:`replay.filters.p002.compiled.cubature_step`.
"""

from __future__ import annotations

import math
from collections import namedtuple
from typing import NamedTuple

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np

from replay.filters.particles import moments as particle_moments  # the one particle bookkeeping
from replay.filters.particles import weighted_mean  # noqa: F401 (re-exported)
from replay.filters.particles import weights as normalise
from replay.util.kernels import (
    chol_solve_rows,
    cholesky,
    matmul,
    quad,  # noqa: F401 (re-exported)
    symmetrise,
    wrap,  # noqa: F401 (re-exported)
    wrap_angle,
)

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
def copy1(dst, src):
    """dst[:] = src, element by element (numba's array assignment also compiles its shape-error
    message: ~2-4 s more per array rank on a process's first compilation)."""
    for a in range(dst.shape[0]):
        dst[a] = src[a]


@nb.njit(cache=True)
def copy2(dst, src):
    """dst[:, :] = src, element by element (:func:`copy1`)."""
    for a in range(dst.shape[0]):
        for b in range(dst.shape[1]):
            dst[a, b] = src[a, b]


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
                sd, cd = sincos_small(wrap_angle(Y[j, i] - ref))
                ss += sd
                cc += cd
            mean[i] = wrap_angle(ref + math.atan2(ss, cc))
        else:
            t = 0.0
            for j in range(c):
                t += Y[j, i]
            mean[i] = t * (1.0 / c)
    for j in range(c):
        for i in range(m):
            D[j, i] = Y[j, i] - mean[i]
        wrap(D[j], mask)


@nb.njit(cache=True, nogil=True)
def estimate(X, logw, xang, x, P, w):
    """Weighted estimate of every run: the weights w (M, N) normalised from ``logw`` (which is
    renormalised in place), the weighted (circular) mean x (M, n) and covariance P (M, n, n)
    with wrapped deviations: the kernels of :mod:`replay.filters.particles`."""
    for m in range(X.shape[0]):
        normalise(logw[m], w[m])
        particle_moments(X[m], w[m], xang, x[m], P[m])


# --- the strong-tracking fading factor (002 §2.2.2): one kernel for the STCKF and the STCPF proposal ---
class Fading(NamedTuple):
    """The STCKF's settings (:data:`replay.filters.p002.stckf.STCKF_PARAMS`): forgetting factor ``rho``,
    weakening factor ``beta``, and whether M is the propagated form (else H Phi H' as printed)."""

    rho: float
    beta: float
    propagated: bool

    @classmethod
    def of(cls, flt) -> "Fading":
        """The settings of a filter declaring ``rho``, ``beta``, ``m_form`` (typed for the kernels)."""
        return cls(float(flt.rho), float(flt.beta), flt.m_form == "propagated")


@nb.njit(cache=True)
def frobenius(A, B):
    """sum(A * B) (the trace of A B') summed in index order, as ``np.sum(A * B)``, without the temporary."""
    t = 0.0
    for a in range(A.shape[0]):
        for b in range(A.shape[1]):
            t += A[a, b] * B[a, b]
    return t


@nb.njit(cache=True, nogil=True)
def fading_factor(V, e, fresh, H, F, P, Q, R, st, work):
    """The fading factor lambda of :mod:`replay.filters.p002.stckf` (002 §2.2.2), st a :class:`Fading`:

        V = e e' (``fresh``) or (rho V + e e') / (1 + rho)     (in place; e = z - h(x^-) (nz,))
        tr N = tr V - beta tr R - tr(H Q H')
        tr M = tr(H F P F' H') = sum((H F P) * (H F))   (propagated; P = 0: nothing propagated)
             = tr(H F H')                               (as printed)
        lambda = max(1, tr N / tr M), 1 when tr M <= 0

    H (nz, n) the Jacobian of h at the prediction, F (n, n) that of f at the previous estimate,
    P its covariance, Q, R (nz, nz); ``work`` = (HQ, HF, HFP) (nz, n) work arrays. Sums in index order."""
    HQ, HF, HFP = work
    rho = st.rho
    for a in range(e.shape[0]):
        for b in range(e.shape[0]):
            ee = e[a] * e[b]
            V[a, b] = ee if fresh else (rho * V[a, b] + ee) / (1.0 + rho)
    trN = np.trace(V) - st.beta * np.trace(R)
    matmul(H, Q, HQ)
    matmul(H, F, HF)
    trN -= frobenius(HQ, H)
    if st.propagated:
        matmul(HF, P, HFP)
        trM = frobenius(HFP, HF)
    else:
        trM = frobenius(HF, H)
    return max(1.0, trN / trM) if trM > 0 else 1.0


# --- the cubature step's pieces without model kernels (replay.filters.p002.compiled.cubature_step) ---
class Proposal(NamedTuple):
    """What one :func:`replay.filters.p002.compiled.cubature_step` computes: the settings of
    :class:`replay.filters.p002.stcpf.CubatureParticleFilter` at one step."""

    stckf: bool  # the STCKF proposal (fading factor), else the CKF's
    fading: Fading  # the STCKF's settings
    scale_prior: bool  # the fading factor scales the prior covariance too
    transition: bool  # predict with the transition density N(f(x^i), Q), else the cubature prediction
    have_L: bool  # L holds the Cholesky factors of P
    have_V: bool  # V holds the innovation averages (else they restart)
    logdet_Q: float
    logdet_R: float
    nzf: int  # the model's measurement size (the length of h(x))


# The cubature step's and the swarm's arguments that travel together (namedtuples of arrays):
Particles = namedtuple("Particles", "X P L V logw lam repairs")  # (M, N, ...) each, changed in place
Noise = namedtuple("Noise", "Q Qi R Ri xang zang")  # Q, R of the measured components, their inverses,
# the state's and the measured components' angle flags
Fit = namedtuple("Fit", "z Ri zang xang logdet_R nzf")  # the swarm's fitness: the measured components z
# (nz,) (a stack (M, nz) for :func:`replay.filters.p002.compiled.swarm_move`), R^-1, their angle flags,
# the state's, log det R and the model's nz
Gwo = namedtuple("Gwo", "a improved xi eps")  # the GWO/IGWO settings: the schedule a (t_max,), IGWO,
# the entropy weights' xi and eps

Work = namedtuple(
    "Work", "fx mean mpost xnew dx zh zh0 ez y d zf Hf Lp Lm Pm Fj Pn Y pts Dx Zc Dz Hj Pxz K Pzz S HQ HF HFP"
)


@nb.njit(cache=True)
def workspace(n, nz, nzf):
    """The work arrays of one particle's cubature step (state size n, nz measured components of the
    model's nzf), allocated once per call of the step and reused by each particle."""
    c = 2 * n
    v, vz, sq, nzn = (n,), (nz,), (n, n), (nz, n)
    return Work(
        np.empty(v),
        np.empty(v),
        np.empty(v),
        np.empty(v),
        np.empty(v),
        np.empty(vz),
        np.empty(vz),
        np.empty(vz),
        np.empty(vz),
        np.empty(vz),
        np.empty(nzf),
        np.empty((nzf, n)),
        np.empty(sq),
        np.empty(sq),
        np.empty(sq),
        np.empty(sq),
        np.empty(sq),
        np.empty((c, n)),
        np.empty((c, n)),
        np.empty((c, n)),
        np.empty((c, nz)),
        np.empty((c, nz)),
        np.empty(nzn),
        np.empty((n, nz)),
        np.empty((n, nz)),
        np.empty((nz, nz)),
        np.empty((nz, nz)),
        np.empty(nzn),
        np.empty(nzn),
        np.empty(nzn),
    )


@nb.njit(cache=True)
def correct(z, R, zang, xang, w):
    """The Kalman correction of the cubature update (Arasaratnam & Haykin 2009) on the work arrays
    ``w``: S = Pzz + R, K = Pxz S^-1, mpost = mean + K (z - zh) (residual and state angles wrapped),
    Pn = Pm - Pxz K', symmetrised. An S without a Cholesky factor gives NaN (the run diverges)."""
    n, nz = w.Pxz.shape
    for a in range(nz):
        for b in range(nz):
            w.S[a, b] = w.Pzz[a, b] + R[a, b]
    chol_solve_rows(w.S, w.Pxz, w.K)
    for a in range(nz):
        w.y[a] = z[a] - w.zh[a]
    wrap(w.y, zang)
    for a in range(n):
        t = 0.0
        for b in range(nz):
            t += w.K[a, b] * w.y[b]
        w.mpost[a] = w.mean[a] + t
    wrap(w.mpost, xang)
    for a in range(n):
        for b in range(n):
            t = 0.0
            for j in range(nz):
                t += w.Pxz[a, j] * w.K[b, j]
            w.Pn[a, b] = w.Pm[a, b] - t
    symmetrise(w.Pn)


@nb.njit(cache=True)
def draw(mean, P, e, L, xang, x):
    """The importance draw x = mean + L e (state angles wrapped), L the factor of P (:func:`factor`,
    written into ``L``). Returns 1 when P was repaired, else 0."""
    repaired = factor(P, L)
    for a in range(x.shape[0]):
        t = 0.0
        for b in range(a + 1):
            t += L[a, b] * e[b]
        x[a] = mean[a] + t
    wrap(x, xang)
    return repaired
