"""The Kalman family's whole runs: every step of M runs in one compiled loop (no Python between steps).

:func:`sigma_run` (UKF, CKF) and :func:`ekf_run` call the step kernels of
:mod:`replay.filters.kalman_kernels` in the order the step-by-step engines call them
(:class:`replay.filters.sigma.SigmaEngine`, :class:`replay.filters.kalman.EKFEngine`),
with work arrays allocated once per call, so they give the engines' numbers bit for bit
(``tests/test_batched.py``). A step may measure a subset of the components, the same for every
run (sensors at their own rates: the fusion task); its update is the steps' update with ``mask``:
the measured components gathered in order, R and the angle flags restricted to them
(:func:`measured`), work arrays of their size. The model's one-state kernels are first-class function
arguments of one declared type (:data:`replay.filters.compiled.ROWS_KERNEL`, ``JACOBIAN_ROWS``):
one compilation (cached by numba) serves every model. When a loop runs:
:func:`replay.filters.compiled.loop_ready`.
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np
from numba import types

from replay.util.kernels import wrap

from .compiled import JACOBIAN_ROWS, ROWS_KERNEL
from .kalman_kernels import (
    Meas,
    Points,
    Rule,
    joseph_update_into,
    propagate_cov_into,
    sigma_points_into,
    sigma_predict_into,
    sigma_update_into,
)

COMPILE_AT = 200_000  # run-steps from which a missing run loop is compiled (~10 s, once per machine)
# The loops' arguments that travel together (namedtuples of arrays; fields as in :func:`sigma_run`):
Obs = namedtuple("Obs", "Z sel R mask")  # measurements (M, steps, nz), measured components, R, angle flags
Params = namedtuple("Params", "Pf Ph Q")  # per step: the kernels' parameters and Q
Out = namedtuple("Out", "X P nis")  # the estimates written: (M, steps, n), (M, steps, n, n), (M, steps)
_VEC, _S2, _S3, _S4 = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1], types.float64[:, :, :, ::1]
_MASK = types.boolean[::1]
_INDEX = types.int64[:, ::1]
_record = types.BaseTuple.from_types  # the numba type of a namedtuple of these field types
_COMMON = (_S2, _S3, _record((_S3, _INDEX, _S3, _MASK), Obs), _record((_S2, _S2, _S3), Params))  # x, P, obs, par
_OUT = _record((_S3, _S4, _S2), Out)
RULE = _record((_S2, _VEC, _VEC), Rule)


@nb.njit(cache=True)
def apply_rows(fun, X, p, out):
    """out[m] = fun(X[m]) for the rows kernel ``fun(X, p, out)`` over the points of every run."""
    for m in range(X.shape[0]):
        fun(X[m], p, out[m])


@nb.njit(cache=True)
def measured(Z, k, sel, zmask, R, z, zm, Rs):
    """The components measured at step k, ``sel[k] = [d, i_0 .. i_{d-1}]`` (in order): z[m] =
    Z[m, k, i], their angle flags zm and R restricted to them, Rs = R[i][:, i] (what the steps
    take with ``mask``: :func:`replay.filters.kalman.measurement`). Returns d."""
    d = sel[k, 0]
    for q in range(d):
        s = sel[k, 1 + q]
        zm[q] = zmask[s]
        for m in range(z.shape[0]):
            z[m, q] = Z[m, k, s]
        for r in range(d):
            Rs[q, r] = R[s, sel[k, 1 + r]]
    return d


@nb.njit(cache=True)
def sigma_update_subset(Zp, obs, k, rule, x, P, xmask, nis, pts, work):
    """:func:`sigma_update_into` on the components measured at step k (:func:`measured` of the
    :data:`Obs` ``obs``), its work arrays views of the flat ``work[2]`` sized for those d components
    (the points' predictions Zp (M, p, nz) gathered into (M, p, d)); ``work[:2]`` = (L (n, n),
    zm (nz,) bool)."""
    M, p, nz = Zp.shape
    sel = obs.sel
    n, d = x.shape[1], sel[k, 0]
    L, zm, work = work
    a, b, c = M * d, M * d + d * d, M * d + d * d + M * p * d  # the views' offsets in ``work``
    z, Rs, Zc = work[:a].reshape((M, d)), work[a:b].reshape((d, d)), work[b:c].reshape((M, p, d))
    measured(obs.Z, k, sel, obs.mask, obs.R[k % obs.R.shape[0]], z, zm, Rs)
    for m in range(M):
        for i in range(p):
            for q in range(d):
                Zc[m, i, q] = Zp[m, i, sel[k, 1 + q]]
    a, b = c + M * d, c + M * d + M * d * d
    y, S, Pxz = work[c:a].reshape((M, d)), work[a:b].reshape((M, d, d)), work[b : b + M * n * d].reshape((M, n, d))
    c = b + M * n * d
    zh, Dz = work[c : c + d], work[c + d : c + d + p * d].reshape((p, d))
    a = c + d + p * d
    Lz, K = work[a : a + d * d].reshape((d, d)), work[a + d * d : a + d * d + n * d].reshape((n, d))
    meas = Meas(Zc, z, Rs, zm[:d])
    return sigma_update_into(meas, pts.dev, rule, x, P, xmask, nis, pts, (y, S, Pxz, (zh, Dz), (Lz, K), L), None)


SIGMA_RUN = types.int64(ROWS_KERNEL, ROWS_KERNEL, *_COMMON, RULE, types.boolean, _MASK, _OUT)
EKF_RUN = types.int64(ROWS_KERNEL, ROWS_KERNEL, JACOBIAN_ROWS, JACOBIAN_ROWS, *_COMMON, _MASK, _OUT)


@nb.njit(cache=True, nogil=True)
def sigma_run(f, h, x, P, obs, par, rule, at_f, xmask, out):
    """M runs of a UKF/CKF over every step: the steps of
    :class:`replay.filters.sigma.SigmaEngine` (points of the state, f, :func:`sigma_predict`, h,
    :func:`sigma_update`) in one loop. x (M, n), P (M, n, n) start values (changed in place);
    ``obs`` (:data:`Obs`): Z (M, steps, nz); ``sel[k] = [d, i_0 .. i_{d-1}]`` the components
    measured at step k, the same for every run (:func:`measured`; d = 0: no update, the prediction
    is the estimate, its NIS NaN); R[k] (a stack of one: the same at every step) and the angle
    flags of z; ``par`` (:data:`Params`), per step k: Pf[k], Ph[k] the kernels' parameters, Q[k]
    (a stack of one as R); ``rule``: the :data:`replay.filters.kalman_kernels.Rule`; ``at_f``: the
    predicted mean is f(x) (:attr:`replay.model.Model.mean_at_f`). Writes ``out`` (:data:`Out`):
    X (M, steps, n), P (M, steps, n, n), nis (M, steps). Returns -1, or the step at which a
    covariance had no Cholesky factor (the caller redoes the runs step by step)."""
    Z, sel, R, zmask = obs
    Pf, Ph, Q = par
    Xout, Pout, nis = out
    M, steps, nz = Z.shape
    p, n = rule.xi.shape
    X, dev, Y, Zp = np.empty((M, p, n)), np.empty((M, p, n)), np.empty((M, p, n)), np.empty((M, p, nz))
    D, L, K, zm = np.empty((p, n)), np.empty((n, n)), np.empty((n, nz)), np.empty(nz, np.bool_)
    z, y, S, Pxz = np.empty((M, nz)), np.empty((M, nz)), np.empty((M, nz, nz)), np.empty((M, n, nz))
    zh, Dz, Lz = np.empty(nz), np.empty((p, nz)), np.empty((nz, nz))
    work = np.empty(M * nz * (2 + p + nz + n) + nz * (1 + p + 2 * nz + n))  # of a subset's update
    pts = Points(X, dev)  # the records and work tuples built once, not per step
    predict_work, update_work, subset_work = (D, L), (y, S, Pxz, (zh, Dz), (Lz, K), L), (L, zm, work)
    if sigma_points_into(x, P, rule.xi, X, dev, L) >= 0:
        return 0
    xc = np.empty((M, n))
    for k in range(steps):
        apply_rows(f, X, Pf[k], Y)
        if at_f:
            f(x, Pf[k], xc)
            for m in range(M):
                wrap(xc[m], xmask)
            x[:] = xc
        if sigma_predict_into(Y, rule, xmask, Q[k % Q.shape[0]], x, P, pts, predict_work, at_f) >= 0:
            return k
        d = sel[k, 0]
        if d == 0:
            Xout[:, k] = x
            Pout[:, k] = P
            nis[:, k] = np.nan
            continue
        apply_rows(h, X, Ph[k], Zp)
        if d == nz:  # every component: the arrays as they are
            for m in range(M):
                for q in range(nz):
                    z[m, q] = Z[m, k, q]
            meas = Meas(Zp, z, R[k % R.shape[0]], zmask)
            bad = sigma_update_into(meas, dev, rule, x, P, xmask, nis[:, k], pts, update_work, None)  # no gate: a
            # gated model steps in Python (kalman.run_kernels)
        else:  # the measured components
            bad = sigma_update_subset(Zp, obs, k, rule, x, P, xmask, nis[:, k], pts, subset_work)
        if 0 <= bad < M:
            return k
        Xout[:, k] = x
        Pout[:, k] = P
        if bad >= M and k + 1 < steps:
            return k + 1
    return -1


@nb.njit(cache=True, nogil=True)
def ekf_run(f, h, F, H, x, P, obs, par, xmask, out):
    """M runs of the EKF over every step (measurements as in :func:`sigma_run`): the steps of
    :class:`replay.filters.kalman.EKFEngine` (F and f at the state, x wrapped,
    :func:`propagate_cov`; H and h at the prediction, y = z - h wrapped, :func:`joseph_update`
    on the measured components) in one loop. Arguments as :func:`sigma_run`. Returns -1, or the
    step at which S had no Cholesky factor."""
    Z, sel, R, zmask = obs
    Pf, Ph, Q = par
    Xout, Pout, nis = out
    M, steps, nz = Z.shape
    n = x.shape[1]
    Fj, Hj, xp, zh = np.empty((M, n, n)), np.empty((M, nz, n)), np.empty((M, n)), np.empty((M, nz))
    Pp, FP, A, AP = np.empty((M, n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    y, PHt, S, K = np.empty((M, nz)), np.empty((n, nz)), np.empty((nz, nz)), np.empty((n, nz))
    L, KR = np.empty((nz, nz)), np.empty((n, nz))
    wz, wy, wH, wR = np.empty(M * nz), np.empty(M * nz), np.empty(M * nz * n), np.empty(nz * nz)
    wPHt, wS, wK, wL, wKR = np.empty(n * nz), np.empty(nz * nz), np.empty(n * nz), np.empty(nz * nz), np.empty(n * nz)
    zm = np.empty(nz, np.bool_)
    work = (PHt, S, K, L, A, AP, KR)
    for k in range(steps):
        F(x, Pf[k], Fj)
        f(x, Pf[k], xp)
        for m in range(M):
            wrap(xp[m], xmask)
        propagate_cov_into(Fj, P, Q[k % Q.shape[0]], Pp, FP)
        d = sel[k, 0]
        if d == 0:
            x[:] = xp
            P[:] = Pp
            Xout[:, k] = x
            Pout[:, k] = P
            nis[:, k] = np.nan
            continue
        H(xp, Ph[k], Hj)
        h(xp, Ph[k], zh)
        if d == nz:  # every component: the arrays as they are (no copies)
            for m in range(M):
                for q in range(nz):
                    y[m, q] = Z[m, k, q] - zh[m, q]
                wrap(y[m], zmask)
            bad = joseph_update_into(xp, Pp, y, Hj, R[k % R.shape[0]], xmask, nis[:, k], work, None)  # no gate: a
            # gated model steps in Python (kalman.run_kernels)
        else:  # the measured components, into work arrays of their size
            z, yd, Rs = wz[: M * d].reshape((M, d)), wy[: M * d].reshape((M, d)), wR[: d * d].reshape((d, d))
            Hs = wH[: M * d * n].reshape((M, d, n))
            measured(Z, k, sel, zmask, R[k % R.shape[0]], z, zm, Rs)
            for m in range(M):
                for q in range(d):
                    s = sel[k, 1 + q]
                    yd[m, q] = z[m, q] - zh[m, s]
                    for j in range(n):
                        Hs[m, q, j] = Hj[m, s, j]
                wrap(yd[m], zm[:d])
            nd, dd = n * d, d * d
            sub = (
                wPHt[:nd].reshape((n, d)),
                wS[:dd].reshape((d, d)),
                wK[:nd].reshape((n, d)),
                wL[:dd].reshape((d, d)),
                A,
                AP,
                wKR[:nd].reshape((n, d)),
            )
            bad = joseph_update_into(xp, Pp, yd, Hs, Rs, xmask, nis[:, k], sub, None)
        if bad >= 0:
            return k
        x[:] = xp
        P[:] = Pp
        Xout[:, k] = x
        Pout[:, k] = P
    return -1
