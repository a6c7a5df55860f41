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
readable reference (``tests/pure.py``: equal bit for bit). The ``*_into`` forms take their
work arrays from the caller, as one tuple ``work`` (the whole-run loops of
:mod:`replay.filters.kalman_loops` allocate them once per run, not once per step); the plain forms
allocate them and call the ``_into`` form. Arrays that travel together are packed into the
namedtuples below (:data:`Rule`, :data:`Meas`, :data:`Points`; a gated update's
:data:`replay.filters.gating.Gate`), so no kernel takes more than 10 arguments.
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np

from .gating import gate
from replay.util.kernels import (
    cholesky,
    deviations,
    matmul,
    point_mean,
    solve_rows,
    symmetrise,
    weighted_outer,
    whitened_norm2,
    wrap,
)

# The arrays that travel together, packed (numba takes namedtuples of arrays as arguments; their
# fields unpack at no cost in the compiled code):
Rule = namedtuple("Rule", "xi wm wc")  # a sigma-point rule: unit points xi (p, n), weights wm, wc (p,)
Meas = namedtuple("Meas", "Z z R mask")  # the points' predicted measurements Z (M, p, nz), the
# measurements z (M, nz), their noise R (nz, nz) and angle flags (nz,)
Points = namedtuple("Points", "X dev")  # sigma points X (M, p, n) and their deviations from the mean


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
    return kalman_correct_into(x, P, y, S, Pxz, xmask, nis, (np.empty((nz, nz)), np.empty((nx, nz))), None)


@nb.njit(cache=True)
def kalman_correct_into(x, P, y, S, Pxz, xmask, nis, work, gates):
    """:func:`kalman_correct` with its work arrays ``work`` = (L (nz, nz), K (nx, nz)) given (the run
    loops allocate them once per run, not once per step), after the gating of each run
    (:func:`replay.filters.gating.gate` with ``gates``, a :class:`replay.filters.gating.Gate`:
    ``group`` (nz,), ``limit2`` (G,); counts into rej (M, G), the components cut into cut (M,);
    None: no gate)."""
    M, nx, nz = Pxz.shape
    L, K = work
    for m in range(M):
        if gates is not None:  # None: no gate (that branch compiled away)
            gates.cut[m] = gate(y[m], S[m], Pxz[m], gates.group, gates.limit2, gates.rej[m])
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
    return sigma_points_into(x, P, xi, X, dev, np.empty((x.shape[1], x.shape[1])))


@nb.njit(cache=True)
def sigma_points_into(x, P, xi, X, dev, L):
    """:func:`sigma_points` with its work array L (n, n) given."""
    M, n = x.shape
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
def sigma_moments(Y, wm, wc, mask, Q, mean, cov, at_f=False):
    """The predicted moments of each run m of the points Y (M, p, n) (the unscented transform):
    mean[m] = sum wm_i Y_i (circular for ``mask``), cov[m] = sum wc_i D_i D_i' + Q with
    D_i = Y_i - mean[m] (``mask`` wrapped). ``at_f``: mean[m] is given (f of the prior mean,
    :attr:`replay.model.Model.mean_at_f`) and kept; the covariance is taken about it."""
    return sigma_moments_into(Y, wm, wc, mask, Q, mean, cov, np.empty(Y.shape[1:]), at_f)


@nb.njit(cache=True)
def sigma_moments_into(Y, wm, wc, mask, Q, mean, cov, D, at_f=False):
    """:func:`sigma_moments` with its work array D (p, n) given."""
    M, p, n = Y.shape
    for m in range(M):
        if not at_f:
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
    return innovation_moments_into(Z, dev, z, wm, wc, mask, y, Pzz, Pxz, (np.empty(nz), np.empty((p, nz))))


@nb.njit(cache=True)
def innovation_moments_into(Z, dev, z, wm, wc, mask, y, Pzz, Pxz, work):
    """:func:`innovation_moments` with its work arrays ``work`` = (zh (nz,), Dz (p, nz)) given."""
    M, p, nz = Z.shape
    zh, Dz = work
    for m in range(M):
        point_mean(Z[m], wm, mask, zh)
        deviations(Z[m], zh, mask, Dz)
        for q in range(nz):
            y[m, q] = z[m, q] - zh[q]
        wrap(y[m], mask)
        weighted_outer(Dz, Dz, wc, Pzz[m])
        weighted_outer(dev[m], Dz, wc, Pxz[m])


@nb.njit(cache=True)
def sigma_predict(Y, rule, xmask, Q, mean, cov, pts, at_f=False):
    """The sigma-point prediction of each run m and the points of the update (one call per step):
    :func:`sigma_moments` of the propagated points Y (M, p, n) with the weights of ``rule`` (a
    :data:`Rule`) into mean, cov (``at_f``: mean given), then :func:`sigma_points` of (mean, cov)
    with its unit points into ``pts`` (:data:`Points`: X, dev). Returns -1, or the first run
    whose predicted covariance is not positive definite (its points, and later runs', not made)."""
    n = Y.shape[2]
    return sigma_predict_into(Y, rule, xmask, Q, mean, cov, pts, (np.empty(Y.shape[1:]), np.empty((n, n))), at_f)


@nb.njit(cache=True)
def sigma_predict_into(Y, rule, xmask, Q, mean, cov, pts, work, at_f=False):
    """:func:`sigma_predict` with its work arrays ``work`` = (D (p, n), L (n, n)) given."""
    D, L = work
    sigma_moments_into(Y, rule.wm, rule.wc, xmask, Q, mean, cov, D, at_f)
    return sigma_points_into(mean, cov, rule.xi, pts.X, pts.dev, L)


@nb.njit(cache=True)
def sigma_update(meas, dev, rule, x, P, xmask, nis, pts):
    """:func:`sigma_update_gated` without gates."""
    return sigma_update_gated(meas, dev, rule, x, P, xmask, nis, pts, None)


@nb.njit(cache=True)
def sigma_update_gated(meas, dev, rule, x, P, xmask, nis, pts, gates):
    """The sigma-point update of each run m, in place on x (M, n), P (M, n, n): the
    :func:`innovation_moments` of the points' predictions ``meas.Z`` (M, p, nz) (``meas`` a
    :data:`Meas`: with the measurements z, R, the angle flags; ``dev`` (M, p, n) the points' state
    deviations), then S = Pzz + R and :func:`kalman_correct`; then the points ``pts`` (X, dev
    (M, p, n)) of the corrected (x, P) (:func:`sigma_points`); gated as :func:`kalman_correct_into`.
    Returns -1; or 0 <= m < M, the first run whose S is not positive definite (x, P of runs >= m
    unchanged, no points); or M + m, the first run whose corrected P has no Cholesky factor (its
    points, and later runs', not made)."""
    M, p, nz = meas.Z.shape
    n = x.shape[1]
    work = (
        np.empty((M, nz)),
        np.empty((M, nz, nz)),
        np.empty((M, n, nz)),
        (np.empty(nz), np.empty((p, nz))),
        (np.empty((nz, nz)), np.empty((n, nz))),
        np.empty((n, n)),
    )
    return sigma_update_into(meas, dev, rule, x, P, xmask, nis, pts, work, gates)


@nb.njit(cache=True)
def sigma_update_into(meas, dev, rule, x, P, xmask, nis, pts, work, gates):
    """:func:`sigma_update_gated` with its work arrays ``work`` = (y, S, Pxz, (zh, Dz), (Lz, K), L)
    given: y (M, nz), S (M, nz, nz), Pxz (M, n, nz), zh (nz,), Dz (p, nz), Lz (nz, nz), K (n, nz),
    L (n, n) (the pairs as the callees take them: no tuple built per call)."""
    M, p, nz = meas.Z.shape
    y, S, Pxz, moments_work, correct_work, L = work
    innovation_moments_into(meas.Z, dev, meas.z, rule.wm, rule.wc, meas.mask, y, S, Pxz, moments_work)
    R = meas.R
    for m in range(M):
        for a in range(nz):
            for b in range(nz):
                S[m, a, b] += R[a, b]
    bad = kalman_correct_into(x, P, y, S, Pxz, xmask, nis, correct_work, gates)
    if bad >= 0:
        return bad
    bad = sigma_points_into(x, P, rule.xi, pts.X, pts.dev, L)
    return -1 if bad < 0 else M + bad


@nb.njit(cache=True)
def propagate_cov(F, P, Q, out):
    """out[m] = F[m] P[m] F[m]' + Q for each run m (the EKF's predicted covariance)."""
    n = P.shape[1]
    propagate_cov_into(F, P, Q, out, np.empty((n, n)))


@nb.njit(cache=True)
def propagate_cov_into(F, P, Q, out, FP):
    """:func:`propagate_cov` with its work array FP (n, n) given."""
    M, n = P.shape[0], P.shape[1]
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
    """:func:`joseph_update_gated` without gates."""
    return joseph_update_gated(x, P, y, H, R, xmask, nis, None)


@nb.njit(cache=True)
def joseph_update_gated(x, P, y, H, R, xmask, nis, gates):
    """The Kalman update in Joseph form, in place on each run m of x (M, n), P (M, n, n), with
    innovations y (M, nz), measurement Jacobians H (M, nz, n) and R (nz, nz) (Bar-Shalom et al.
    2001, §5.2), after the gating of each run (:func:`replay.filters.gating.gate` on S and P H'):

        S = H P H' + R,  K = P H' S^-1,  x = x + K y  (``xmask`` components wrapped),
        P = (I - K H) P (I - K H)' + K R K',  symmetrised;  nis = y' S^-1 y.

    Returns the first run whose S is not positive definite (that run and the later ones are
    left as they were), or -1."""
    M, n = x.shape
    nz = y.shape[1]
    work = (
        np.empty((n, nz)),
        np.empty((nz, nz)),
        np.empty((n, nz)),
        np.empty((nz, nz)),
        np.empty((n, n)),
        np.empty((n, n)),
        np.empty((n, nz)),
    )
    return joseph_update_into(x, P, y, H, R, xmask, nis, work, gates)


@nb.njit(cache=True)
def joseph_update_into(x, P, y, H, R, xmask, nis, work, gates):
    """:func:`joseph_update_gated` with its work arrays ``work`` = (PHt, S, K, L, A, AP, KR) given:
    PHt, K, KR (n, nz), S, L (nz, nz), A, AP (n, n)."""
    M, n = x.shape
    nz = y.shape[1]
    PHt, S, K, L, A, AP, KR = work
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
        if gates is not None:
            gates.cut[m] = gate(y[m], S, PHt, gates.group, gates.limit2, gates.rej[m])
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
