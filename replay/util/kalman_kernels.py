"""Compiled (numba) steps of the Kalman family over a leading Monte Carlo run axis.

The arithmetic of :mod:`replay.filters.kalman` (EKF: :func:`propagate_cov`,
:func:`joseph_update`) and :mod:`replay.filters.sigma` (UKF, CKF:
:func:`sigma_points`, :func:`sigma_moments`, :func:`innovation_moments`,
:func:`kalman_correct`, and their fusions :func:`sigma_predict` and
:func:`sigma_update`, one compiled call each per step), written once as loops
over the leaves of :mod:`replay.util.kernels`. Every function takes stacks
(x (M, n), P (M, n, n), points (M, p, n)) and treats each run alone with the
same loops, so a run's numbers do not depend on the other runs of its stack
(one run is a stack of one). Each function's un-jitted ``py_func`` is the
readable reference (``tests/pure.py``: equal bit for bit).
"""
from __future__ import annotations

import logging

import numba as nb
import numpy as np
from numba import types

from .kernels import (cholesky, deviations, matmul, point_mean, solve_rows, symmetrise, weighted_outer,
                      whitened_norm2, wrap)


@nb.njit(cache=True)
def gain(S, B, y, L, K):
    """The gain K = B S^-1 (B = Pxz, or P H') and the NIS y' S^-1 y through one Cholesky factor L
    of S; returns the NIS, or -1.0 when S is not positive definite (K not computed)."""
    if not cholesky(S, L):
        return -1.0
    solve_rows(L, B, K)
    return whitened_norm2(L, y)


@nb.njit(cache=True)
def shift_mean(x, K, y, xmask):
    """x = x + K y in place, the ``xmask`` components wrapped."""
    for i in range(x.shape[0]):
        t = 0.0
        for j in range(y.shape[0]):
            t += K[i, j] * y[j]
        x[i] += t
    wrap(x, xmask)


@nb.njit(cache=True)
def gain_nis(S, Pxz, y, K, nis):
    """For each run m of the stacks S (M, nz, nz), Pxz (M, nx, nz), y (M, nz): the gain
    K[m] = Pxz[m] S[m]^-1 and nis[m] = y[m]' S[m]^-1 y[m] (Bar-Shalom et al. 2001, eq. 5.2.3-14
    and §5.4.2). Returns the first run whose S is not positive definite (its K and the later
    runs' are not computed), or -1."""
    M, nx, nz = Pxz.shape
    L = np.empty((nz, nz))
    for m in range(M):
        nis[m] = gain(S[m], Pxz[m], y[m], L, K[m])
        if nis[m] < 0.0:
            return m
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
        g = gain(S[m], Pxz[m], y[m], L, K)
        if g < 0.0:
            return m
        nis[m] = g
        shift_mean(x[m], K, y[m], xmask)
        for i in range(nx):
            for j in range(nx):
                t = 0.0
                for q in range(nz):
                    t += K[i, q] * Pxz[m, j, q]
                P[m, i, j] -= t
        symmetrise(P[m])
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


@nb.njit(cache=True)
def sigma_moments(Y, wm, wc, mask, Q, mean, cov):
    """The predicted moments of each run m of the points Y (M, p, n) (the unscented transform):
    mean[m] = sum wm_i Y_i (circular for ``mask``), cov[m] = sum wc_i D_i D_i' + Q with
    D_i = Y_i - mean[m] (``mask`` wrapped)."""
    M, p, n = Y.shape
    D = np.empty((p, n))
    for m in range(M):
        point_mean(Y[m], wm, mask, mean[m])
        deviations(Y[m], mean[m], mask, D)
        weighted_outer(D, D, wc, cov[m])
        for a in range(n):
            for b in range(n):
                cov[m, a, b] += Q[a, b]


@nb.njit(cache=True)
def innovation_moments(Z, dev, z, wm, wc, mask, y, Pzz, Pxz):
    """The measurement moments of each run m of the points' predictions Z (M, p, nz), their
    state deviations ``dev`` (M, p, nx) and the measurements z (M, nz): the predicted
    measurement zh = sum wm_i Z_i (circular for ``mask``), Dz_i = Z_i - zh (wrapped),
    y = z - zh (wrapped), Pzz = sum wc_i Dz_i Dz_i', Pxz = sum wc_i dev_i Dz_i'."""
    M, p, nz = Z.shape
    zh = np.empty(nz)
    Dz = np.empty((p, nz))
    for m in range(M):
        point_mean(Z[m], wm, mask, zh)
        deviations(Z[m], zh, mask, Dz)
        for q in range(nz):
            y[m, q] = z[m, q] - zh[q]
        wrap(y[m], mask)
        weighted_outer(Dz, Dz, wc, Pzz[m])
        weighted_outer(dev[m], Dz, wc, Pxz[m])


@nb.njit(cache=True)
def sigma_predict(Y, wm, wc, xmask, Q, xi, mean, cov, X, dev):
    """The sigma-point prediction of each run m and the points of the update (one call per step):
    :func:`sigma_moments` of the propagated points Y (M, p, n) into mean, cov, then
    :func:`sigma_points` of (mean, cov) into X, dev. Returns -1, or the first run whose
    predicted covariance is not positive definite (its points, and later runs', not made)."""
    sigma_moments(Y, wm, wc, xmask, Q, mean, cov)
    return sigma_points(mean, cov, xi, X, dev)


@nb.njit(cache=True)
def sigma_update(Z, dev, z, wm, wc, zmask, R, x, P, xmask, nis, xi, X, Xdev):
    """The sigma-point update of each run m, in place on x (M, n), P (M, n, n): the
    :func:`innovation_moments` of the points' predictions Z (M, p, nz), then S = Pzz + R and
    :func:`kalman_correct`; then the points X, Xdev (M, p, n) of the corrected (x, P)
    (:func:`sigma_points`). Returns -1; or 0 <= m < M, the first run whose S is not positive
    definite (x, P of runs >= m unchanged, no points); or M + m, the first run whose corrected
    P has no Cholesky factor (its points, and later runs', not made)."""
    M, p, nz = Z.shape
    y, S, Pxz = np.empty((M, nz)), np.empty((M, nz, nz)), np.empty((M, x.shape[1], nz))
    innovation_moments(Z, dev, z, wm, wc, zmask, y, S, Pxz)
    for m in range(M):
        for a in range(nz):
            for b in range(nz):
                S[m, a, b] += R[a, b]
    bad = kalman_correct(x, P, y, S, Pxz, xmask, nis)
    if bad >= 0:
        return bad
    bad = sigma_points(x, P, xi, X, Xdev)
    return -1 if bad < 0 else M + bad


@nb.njit(cache=True)
def propagate_cov(F, P, Q, out):
    """out[m] = F[m] P[m] F[m]' + Q for each run m (the EKF's predicted covariance)."""
    M, n = P.shape[0], P.shape[1]
    FP = np.empty((n, n))
    for m in range(M):
        matmul(F[m], P[m], FP)
        for i in range(n):
            for j in range(n):
                t = 0.0
                for q in range(n):
                    t += FP[i, q] * F[m, j, q]
                out[m, i, j] = t + Q[i, j]


@nb.njit(cache=True)
def joseph_update(x, P, y, H, R, xmask, nis):
    """The Kalman update in Joseph form, in place on each run m of x (M, n), P (M, n, n), with
    innovations y (M, nz), measurement Jacobians H (M, nz, n) and R (nz, nz) (Bar-Shalom et al.
    2001, §5.2):

        S = H P H' + R,  K = P H' S^-1,  x = x + K y  (``xmask`` components wrapped),
        P = (I - K H) P (I - K H)' + K R K',  symmetrised;  nis = y' S^-1 y.

    Returns the first run whose S is not positive definite (that run and the later ones are
    left as they were), or -1."""
    M, n = x.shape
    nz = y.shape[1]
    PHt, S, K = np.empty((n, nz)), np.empty((nz, nz)), np.empty((n, nz))
    L, A, AP, KR = np.empty((nz, nz)), np.empty((n, n)), np.empty((n, n)), np.empty((n, nz))
    for m in range(M):
        for i in range(n):
            for j in range(nz):
                t = 0.0
                for q in range(n):
                    t += P[m, i, q] * H[m, j, q]
                PHt[i, j] = t
        matmul(H[m], PHt, S)
        for i in range(nz):
            for j in range(nz):
                S[i, j] += R[i, j]
        g = gain(S, PHt, y[m], L, K)
        if g < 0.0:
            return m
        nis[m] = g
        shift_mean(x[m], K, y[m], xmask)
        for i in range(n):  # A = I - K H
            for j in range(n):
                t = 0.0
                for q in range(nz):
                    t += K[i, q] * H[m, q, j]
                A[i, j] = (1.0 if i == j else 0.0) - t
        matmul(A, P[m], AP)
        matmul(K, R, KR)
        for i in range(n):
            for j in range(n):
                t = 0.0
                for q in range(n):
                    t += AP[i, q] * A[j, q]
                u = 0.0
                for q in range(nz):
                    u += KR[i, q] * K[j, q]
                P[m, i, j] = t + u
        symmetrise(P[m])
    return -1



# --- whole runs: the steps above in one compiled loop, the model's one-state kernels passed in ---
# The kernels are first-class function arguments of one declared type, so that the loop is
# compiled once per machine for every model (and cached), not once per model and process.
_VEC, _MAT = types.float64[::1], types.float64[:, ::1]
ROW_KERNEL = types.FunctionType(types.void(_VEC, _VEC, _VEC))      # f, h: (x, p, out)
JACOBIAN_KERNEL = types.FunctionType(types.void(_VEC, _VEC, _MAT))  # F, H: (x, p, J)
_S2, _S3, _S4 = types.float64[:, ::1], types.float64[:, :, ::1], types.float64[:, :, :, ::1]
_MASK = types.boolean[::1]
_COMMON = (_S2, _S3, _S3, _MASK, _S2, _S2, _S3, _S3)  # x, P, Z, seen, Pf, Ph, Q, R
_OUT = (_S3, _S4, _S2)  # Xout, Pout, nis


@nb.njit(cache=True)
def apply_rows(fun, X, p, out):
    """out[m, i] = fun(X[m, i]) for the one-state kernel ``fun(x, p, out)`` over a stack of points."""
    for m in range(X.shape[0]):
        for i in range(X.shape[1]):
            fun(X[m, i], p, out[m, i])


SIGMA_RUN = types.int64(ROW_KERNEL, ROW_KERNEL, *_COMMON, _S2, _VEC, _VEC, _MASK, _MASK, *_OUT)
EKF_RUN = types.int64(ROW_KERNEL, ROW_KERNEL, JACOBIAN_KERNEL, JACOBIAN_KERNEL, *_COMMON, _MASK, _MASK, *_OUT)


def loop_ready(loop, sig, compile_ok: bool) -> bool:
    """Whether the run loop ``loop`` (:func:`sigma_run`, :func:`ekf_run`, the PF's ``pf_run``) can
    be called with its declared signature ``sig``: compiled in this process, or loaded from numba's disk
    cache, or (``compile_ok``) compiled now (about 10 s, once per machine). Compiled lazily,
    not at import: a short run never waits for it."""
    if (loop, id(sig)) in _READY:  # numba's ``loop.signatures`` costs 35 µs a call, hashing ``sig`` 30
        return True
    if not loop.signatures:
        if loop._cache.load_overload(sig, loop.targetctx) is None:
            if not compile_ok:
                return False
            logging.getLogger("replay.kernels").info(
                "compiling the run loop %s (about 12 s, once per machine; cached for later runs)",
                loop.__name__)
        loop.compile(sig)
        loop.disable_compile()  # one type for every model: the kernels convert to it
    _READY.add((loop, id(sig)))  # the declared signatures are module constants
    return True


_READY: set = set()


@nb.njit(cache=True, nogil=True)
def sigma_run(f, h, x, P, Z, seen, Pf, Ph, Q, R, xi, wm, wc, xmask, zmask, Xout, Pout, nis):
    """M runs of a UKF/CKF over every step: the steps of
    :class:`replay.filters.sigma.SigmaEngine` (points of the state, f, :func:`sigma_predict`, h,
    :func:`sigma_update`) in one loop. x (M, n), P (M, n, n) start values (changed in place);
    Z (M, steps, nz), every component present at the steps k where ``seen[k]``, none at the
    others (no update there: the prediction is the estimate, its NIS NaN); per step k: Pf[k],
    Ph[k] the kernels' parameters, Q[k], R[k] (a stack of one: the same at every step). Writes
    Xout (M, steps, n), Pout (M, steps, n, n), nis (M, steps). Returns -1, or the step at which
    a covariance had no Cholesky factor (the caller redoes the runs step by step)."""
    M, steps, nz = Z.shape
    p, n = xi.shape
    X, dev, Y, Zp = np.empty((M, p, n)), np.empty((M, p, n)), np.empty((M, p, n)), np.empty((M, p, nz))
    z = np.empty((M, nz))
    if sigma_points(x, P, xi, X, dev) >= 0:
        return 0
    for k in range(steps):
        apply_rows(f, X, Pf[k], Y)
        if sigma_predict(Y, wm, wc, xmask, Q[k % Q.shape[0]], xi, x, P, X, dev) >= 0:
            return k
        if not seen[k]:
            Xout[:, k] = x
            Pout[:, k] = P
            nis[:, k] = np.nan
            continue
        apply_rows(h, X, Ph[k], Zp)
        for m in range(M):
            for q in range(nz):
                z[m, q] = Z[m, k, q]
        bad = sigma_update(Zp, dev, z, wm, wc, zmask, R[k % R.shape[0]], x, P, xmask, nis[:, k], xi, X, dev)
        if 0 <= bad < M:
            return k
        Xout[:, k] = x
        Pout[:, k] = P
        if bad >= M and k + 1 < steps:
            return k + 1
    return -1


@nb.njit(cache=True, nogil=True)
def ekf_run(f, h, F, H, x, P, Z, seen, Pf, Ph, Q, R, xmask, zmask, Xout, Pout, nis):
    """M runs of the EKF over every step (measurements as in :func:`sigma_run`): the steps of
    :class:`replay.filters.kalman.EKFEngine` (F and f at the state, x wrapped,
    :func:`propagate_cov`; H and h at the prediction, y = z - h wrapped, :func:`joseph_update`)
    in one loop. Arguments as :func:`sigma_run`. Returns -1, or the step at which S had no
    Cholesky factor."""
    M, steps, nz = Z.shape
    n = x.shape[1]
    Fj, Hj, xp, y = np.empty((M, n, n)), np.empty((M, nz, n)), np.empty((M, n)), np.empty((M, nz))
    Pp, zh = np.empty((M, n, n)), np.empty(nz)
    for k in range(steps):
        for m in range(M):
            F(x[m], Pf[k], Fj[m])
            f(x[m], Pf[k], xp[m])
            wrap(xp[m], xmask)
        propagate_cov(Fj, P, Q[k % Q.shape[0]], Pp)
        if not seen[k]:
            x[:] = xp
            P[:] = Pp
            Xout[:, k] = x
            Pout[:, k] = P
            nis[:, k] = np.nan
            continue
        for m in range(M):
            H(xp[m], Ph[k], Hj[m])
            h(xp[m], Ph[k], zh)
            for q in range(nz):
                y[m, q] = Z[m, k, q] - zh[q]
            wrap(y[m], zmask)
        if joseph_update(xp, Pp, y, Hj, R[k % R.shape[0]], xmask, nis[:, k]) >= 0:
            return k
        x[:] = xp
        P[:] = Pp
        Xout[:, k] = x
        Pout[:, k] = P
    return -1
