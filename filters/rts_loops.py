"""Rauch–Tung–Striebel backward passes over the Monte Carlo run axis, compiled (numba).

Equations (Särkkä, *Bayesian Filtering and Smoothing*, 2013), for each run and each step k
from the next-to-last down to the first, given the filtered means m_k and covariances P_k
of the forward pass and the smoothed m^s_{k+1}, P^s_{k+1} (m^s_n = m_n, P^s_n = P_n):

    prediction   m-_{k+1}, P-_{k+1} and the cross-covariance C_{k+1} of x_k and x_{k+1}
                 RTS / ERTS (Theorem 8.2, eq. 8.6; §9.1):
                     m-_{k+1} = f(m_k),  P-_{k+1} = F_x P_k F_x' + Q_{k+1},  C_{k+1} = P_k F_x'
                 URTS / cubature RTS (Särkkä 2008; §9.3 and §9.5, the
                 unscented and the cubature rule on the same equations):
                     X_i = m_k + L_k xi_i (L_k L_k' = P_k),  Y_i = f(X_i)
                     m-_{k+1} = sum wm_i Y_i,  P-_{k+1} = sum wc_i (Y_i - m-)(Y_i - m-)' + Q_{k+1}
                     C_{k+1} = sum wc_i (X_i - m_k)(Y_i - m-)'
    gain         G_k = C_{k+1} [P-_{k+1}]^-1               (a Cholesky factor of P-_{k+1})
    smoothed     m^s_k = m_k + G_k (m^s_{k+1} - m-_{k+1})
                 P^s_k = P_k + G_k (P^s_{k+1} - P-_{k+1}) G_k'   (symmetrised)

The angle components declared by the model are wrapped in every difference (Y_i - m-, the
mean difference m^s_{k+1} - m-_{k+1}) and in m-_{k+1} and m^s_k; X_i - m_k is L_k xi_i
exactly. The prediction is the forward pass's own: the same kernels on the same filtered
estimates (:func:`replay.filters.kalman_kernels.propagate_cov_into`,
:func:`~replay.filters.kalman_kernels.sigma_points_into`,
:func:`~replay.filters.kalman_kernels.sigma_moments_into`, ``at_f`` the model's f(mean)), so
what the forward pass predicted is recomputed bit for bit rather than stored: the filters
that do not smooth keep their loops and their memory unchanged.

:func:`ekf_smooth_run` and :func:`sigma_smooth_run` take the model's rows kernels as
first-class functions (:data:`replay.filters.compiled.ROWS_KERNEL`, ``JACOBIAN_ROWS``) as the
forward loops do (:mod:`replay.filters.kalman_loops`); called through their ``py_func`` with
Python functions in their place they are the Python path (:mod:`replay.filters.smoothers`).
Every step kernel treats each run alone: a run's numbers do not depend on its batch.
"""

from __future__ import annotations

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np
from numba import types

from replay.util.kernels import cholesky, deviations, solve_rows, symmetrise, weighted_outer, wrap

from .compiled import JACOBIAN_ROWS, ROWS_KERNEL
from .kalman_kernels import propagate_cov_into, sigma_moments_into, sigma_points_into
from .kalman_loops import RULE

_VEC, _S2, _S3, _S4 = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1], types.float64[:, :, :, ::1]
_MASK = types.boolean[::1]
EKF_SMOOTH = types.int64(ROWS_KERNEL, JACOBIAN_ROWS, _S3, _S4, _S2, _S3, _MASK, _S3, _S4)
SIGMA_SMOOTH = types.int64(ROWS_KERNEL, _S3, _S4, _S2, _S3, RULE, types.boolean, _MASK, _S3, _S4)


@nb.njit(cache=True)
def rts_correct(xf, Pf, xp, Pp, C, xn, Pn, xmask, out, work):
    """The gain and smoothed moments (module docstring; Särkkä 2013 eq. 8.6) of each run m of
    the stacks: filtered xf (M, n), Pf; predicted xp, Pp; cross-covariance C (M, n, n); smoothed
    at the next step xn, Pn. Writes ``out`` = (xs, Ps); ``work`` = (L, G, d, W): L, G, W (n, n),
    d (n,). Returns -1, or the first run whose P-_{k+1} has no Cholesky factor."""
    M, n = xf.shape
    xs, Ps = out
    L, G, d, W = work
    for m in range(M):
        if not cholesky(Pp[m], L):
            return m
        solve_rows(L, C[m], G)  # G = C Pp^-1, row by row
        for i in range(n):
            d[i] = xn[m, i] - xp[m, i]
        wrap(d, xmask)
        for i in range(n):
            t = 0.0
            for j in range(n):
                t += G[i, j] * d[j]
            xs[m, i] = xf[m, i] + t
        wrap(xs[m], xmask)
        for i in range(n):
            for j in range(n):
                t = 0.0
                for q in range(n):
                    t += G[i, q] * (Pn[m, q, j] - Pp[m, q, j])
                W[i, j] = t
        for i in range(n):
            for j in range(n):
                t = 0.0
                for q in range(n):
                    t += W[i, q] * G[j, q]
                Ps[m, i, j] = Pf[m, i, j] + t
        symmetrise(Ps[m])
    return -1


@nb.njit(cache=True)
def ekf_cross(P, F, C):
    """C[m] = P[m] F[m]' (the cross-covariance of x_k and x_{k+1} under the linearisation)."""
    M, n = P.shape[0], P.shape[1]
    for m in range(M):
        for i in range(n):
            for j in range(n):
                t = 0.0
                for q in range(n):
                    t += P[m, i, q] * F[m, j, q]
                C[m, i, j] = t


@nb.njit(cache=True)
def sigma_cross(dev, Y, xp, wc, xmask, C, D):
    """C[m] = sum wc_i dev_i (Y_i - xp)' (``xmask`` wrapped): the points' cross-covariance."""
    for m in range(Y.shape[0]):
        deviations(Y[m], xp[m], xmask, D)
        weighted_outer(dev[m], D, wc, C[m])


@nb.njit(cache=True)
def wrap_rows(x, xmask):
    """Each row of x (M, n) with its ``xmask`` components wrapped, in place."""
    for m in range(x.shape[0]):
        wrap(x[m], xmask)


@nb.njit(cache=True, nogil=True)
def ekf_smooth_run(f, F, X, P, Pf, Q, xmask, Xs, Ps):
    """The (E)RTS backward pass of M runs: filtered X (M, steps, n), P (M, steps, n, n); per
    step k the kernels' parameters Pf[k] and Q[k] (a stack of one: the same at every step), the
    prediction to step k + 1 taking Pf[k + 1], Q[k + 1] as the forward step k + 1 did. Writes
    Xs, Ps. Returns -1, or the step k whose P-_{k+1} had no Cholesky factor."""
    M, steps, n = X.shape
    xk, xp, xs = np.empty((M, n)), np.empty((M, n)), np.empty((M, n))
    Pk, Pp, C, Fj = np.empty((M, n, n)), np.empty((M, n, n)), np.empty((M, n, n)), np.empty((M, n, n))
    xn, Pn, Psk = np.empty((M, n)), np.empty((M, n, n)), np.empty((M, n, n))
    FP, L, G, W, d = np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty(n)
    Xs[:, steps - 1] = X[:, steps - 1]
    Ps[:, steps - 1] = P[:, steps - 1]
    for k in range(steps - 2, -1, -1):
        xk[:] = X[:, k]
        Pk[:] = P[:, k]
        xn[:] = Xs[:, k + 1]
        Pn[:] = Ps[:, k + 1]
        F(xk, Pf[k + 1], Fj)
        f(xk, Pf[k + 1], xp)
        wrap_rows(xp, xmask)
        propagate_cov_into(Fj, Pk, Q[(k + 1) % Q.shape[0]], Pp, FP)
        ekf_cross(Pk, Fj, C)
        if rts_correct(xk, Pk, xp, Pp, C, xn, Pn, xmask, (xs, Psk), (L, G, d, W)) >= 0:
            return k
        Xs[:, k] = xs
        Ps[:, k] = Psk
    return -1


@nb.njit(cache=True, nogil=True)
def sigma_smooth_run(f, X, P, Pf, Q, rule, at_f, xmask, Xs, Ps):
    """The unscented (UKF points) or cubature (CKF points) RTS backward pass of M runs: ``rule``
    the forward filter's points xi (p, n) and weights (:data:`replay.filters.kalman_kernels.Rule`);
    ``at_f``: the predicted mean is f(m_k) (the forward filter's,
    :attr:`replay.model.Model.mean_at_f`); else as :func:`ekf_smooth_run`."""
    xi, wm, wc = rule
    M, steps, n = X.shape
    p = xi.shape[0]
    xk, xp, xs, xn = np.empty((M, n)), np.empty((M, n)), np.empty((M, n)), np.empty((M, n))
    Pk, Pp, C = np.empty((M, n, n)), np.empty((M, n, n)), np.empty((M, n, n))
    Pn, Psk = np.empty((M, n, n)), np.empty((M, n, n))
    Sg, dev, Y = np.empty((M, p, n)), np.empty((M, p, n)), np.empty((M, p, n))
    D, L, G, W, d = np.empty((p, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty(n)
    Xs[:, steps - 1] = X[:, steps - 1]
    Ps[:, steps - 1] = P[:, steps - 1]
    for k in range(steps - 2, -1, -1):
        xk[:] = X[:, k]
        Pk[:] = P[:, k]
        xn[:] = Xs[:, k + 1]
        Pn[:] = Ps[:, k + 1]
        if sigma_points_into(xk, Pk, xi, Sg, dev, L) >= 0:
            return k
        f(Sg.reshape((M * p, n)), Pf[k + 1], Y.reshape((M * p, n)))  # every point of every run: one call
        if at_f:
            f(xk, Pf[k + 1], xp)
            wrap_rows(xp, xmask)
        sigma_moments_into(Y, wm, wc, xmask, Q[(k + 1) % Q.shape[0]], xp, Pp, D, at_f)
        sigma_cross(dev, Y, xp, wc, xmask, C, D)
        if rts_correct(xk, Pk, xp, Pp, C, xn, Pn, xmask, (xs, Psk), (L, G, d, W)) >= 0:
            return k
        Xs[:, k] = xs
        Ps[:, k] = Psk
    return -1
