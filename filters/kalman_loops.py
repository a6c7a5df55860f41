"""The Kalman family's whole runs: every step of M runs in one compiled loop (no Python between steps).

:func:`sigma_run` (UKF, CKF) and :func:`ekf_run` call the step kernels of
:mod:`replay.filters.kalman_kernels` in the order the step-by-step engines call them
(:class:`replay.filters.sigma.SigmaEngine`, :class:`replay.filters.kalman.EKFEngine`),
with work arrays allocated once per call, so they give the engines' numbers bit for bit
(``tests/test_batched.py``). The model's one-state kernels are first-class function
arguments of one declared type (:data:`replay.filters.compiled.ROWS_KERNEL`, ``JACOBIAN_ROWS``):
one compilation (cached by numba) serves every model. When a loop runs:
:func:`replay.filters.compiled.loop_ready`.
"""

from __future__ import annotations

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np
from numba import types

from replay.util.kernels import wrap

from .compiled import JACOBIAN_ROWS, ROWS_KERNEL
from .kalman_kernels import (
    joseph_update_into,
    propagate_cov_into,
    sigma_points_into,
    sigma_predict_into,
    sigma_update_into,
)

COMPILE_AT = 200_000  # run-steps from which a missing run loop is compiled (~10 s, once per machine)
_VEC, _S2, _S3, _S4 = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1], types.float64[:, :, :, ::1]
_MASK = types.boolean[::1]
_COMMON = (_S2, _S3, _S3, _MASK, _S2, _S2, _S3, _S3)  # x, P, Z, seen, Pf, Ph, Q, R
_OUT = (_S3, _S4, _S2)  # Xout, Pout, nis


@nb.njit(cache=True)
def apply_rows(fun, X, p, out):
    """out[m] = fun(X[m]) for the rows kernel ``fun(X, p, out)`` over the points of every run."""
    for m in range(X.shape[0]):
        fun(X[m], p, out[m])


SIGMA_RUN = types.int64(ROWS_KERNEL, ROWS_KERNEL, *_COMMON, _S2, _VEC, _VEC, types.boolean, _MASK, _MASK, *_OUT)
EKF_RUN = types.int64(ROWS_KERNEL, ROWS_KERNEL, JACOBIAN_ROWS, JACOBIAN_ROWS, *_COMMON, _MASK, _MASK, *_OUT)


@nb.njit(cache=True, nogil=True)
def sigma_run(f, h, x, P, Z, seen, Pf, Ph, Q, R, xi, wm, wc, at_f, xmask, zmask, Xout, Pout, nis):
    """M runs of a UKF/CKF over every step: the steps of
    :class:`replay.filters.sigma.SigmaEngine` (points of the state, f, :func:`sigma_predict`, h,
    :func:`sigma_update`) in one loop. x (M, n), P (M, n, n) start values (changed in place);
    Z (M, steps, nz), every component present at the steps k where ``seen[k]``, none at the
    others (no update there: the prediction is the estimate, its NIS NaN); per step k: Pf[k],
    Ph[k] the kernels' parameters, Q[k], R[k] (a stack of one: the same at every step); ``at_f``:
    the predicted mean is f(x) (:attr:`replay.model.Model.mean_at_f`). Writes
    Xout (M, steps, n), Pout (M, steps, n, n), nis (M, steps). Returns -1, or the step at which
    a covariance had no Cholesky factor (the caller redoes the runs step by step)."""
    M, steps, nz = Z.shape
    p, n = xi.shape
    X, dev, Y, Zp = np.empty((M, p, n)), np.empty((M, p, n)), np.empty((M, p, n)), np.empty((M, p, nz))
    z = np.empty((M, nz))
    D, L, Lz, K = np.empty((p, n)), np.empty((n, n)), np.empty((nz, nz)), np.empty((n, nz))
    y, S, Pxz, zh, Dz = np.empty((M, nz)), np.empty((M, nz, nz)), np.empty((M, n, nz)), np.empty(nz), np.empty((p, nz))
    group = limit2 = rej = cut = None  # no gate: a gated model steps in Python (kalman.run_kernels)
    if sigma_points_into(x, P, xi, X, dev, L) >= 0:
        return 0
    xc = np.empty((M, n))
    for k in range(steps):
        apply_rows(f, X, Pf[k], Y)
        if at_f:
            f(x, Pf[k], xc)
            for m in range(M):
                wrap(xc[m], xmask)
            x[:] = xc
        if sigma_predict_into(Y, wm, wc, xmask, Q[k % Q.shape[0]], xi, x, P, X, dev, D, L, at_f) >= 0:
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
        bad = sigma_update_into(
            Zp,
            dev,
            z,
            wm,
            wc,
            zmask,
            R[k % R.shape[0]],
            x,
            P,
            xmask,
            nis[:, k],
            xi,
            X,
            dev,
            y,
            S,
            Pxz,
            zh,
            Dz,
            Lz,
            K,
            L,
            group,
            limit2,
            rej,
            cut,
        )
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
    Pp, zh = np.empty((M, n, n)), np.empty((M, nz))
    FP, PHt, S, K = np.empty((n, n)), np.empty((n, nz)), np.empty((nz, nz)), np.empty((n, nz))
    L, A, AP, KR = np.empty((nz, nz)), np.empty((n, n)), np.empty((n, n)), np.empty((n, nz))
    group = limit2 = rej = cut = None  # no gate: a gated model steps in Python (kalman.run_kernels)
    for k in range(steps):
        F(x, Pf[k], Fj)
        f(x, Pf[k], xp)
        for m in range(M):
            wrap(xp[m], xmask)
        propagate_cov_into(Fj, P, Q[k % Q.shape[0]], Pp, FP)
        if not seen[k]:
            x[:] = xp
            P[:] = Pp
            Xout[:, k] = x
            Pout[:, k] = P
            nis[:, k] = np.nan
            continue
        H(xp, Ph[k], Hj)
        h(xp, Ph[k], zh)
        for m in range(M):
            for q in range(nz):
                y[m, q] = Z[m, k, q] - zh[m, q]
            wrap(y[m], zmask)
        R_k = R[k % R.shape[0]]
        if (
            joseph_update_into(xp, Pp, y, Hj, R_k, xmask, nis[:, k], PHt, S, K, L, A, AP, KR, group, limit2, rej, cut)
            >= 0
        ):
            return k
        x[:] = xp
        P[:] = Pp
        Xout[:, k] = x
        Pout[:, k] = P
    return -1
