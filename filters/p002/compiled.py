"""The particle-level work of paper 002's filters, compiled with numba: the library's only implementation.

For models that provide numba kernels of ``f``, ``h``, ``F``, ``H``
(:meth:`replay.model.Model.kernels`). This file is a template: the entry
points call the model's kernels as module globals ``f``, ``h``, ``F``, ``H``,
which :func:`replay.filters.compiled.bind` supplies by writing a copy of this
file with the model's imports at the MODEL KERNELS line (so that numba can cache
the compiled code on disk; functions passed as arguments would be recompiled in every
process). The helpers without model kernels (:func:`factor`, :func:`estimate`, ...) live in
:mod:`replay.filters.p002.compiled_util`, imported by its absolute name (the copy lives elsewhere).

* :func:`cubature_step` — one step of every particle's cubature filter (CKF or
  STCKF, 002 §2.2): the prediction, the update with the measured components
  (none: a predict-only step, which draws from the same prediction), the importance draw
  x = m + L e with ``e`` drawn by the caller, and the importance weight
  (002 §2.1), for M runs x N particles;
* :func:`swarm_move` — the ``t_max`` GWO/IGWO iterations (002 §3.1–3.2) of M
  swarms, fitness included, with the uniforms drawn by the caller.

Every random number is drawn by the caller from the run's own generator. A
readable numpy version of the same equations is kept as a test oracle
(``tests/oracle_p002.py``); ``tests/test_compiled.py`` asserts that the two
agree to rounding (1e-9) step by step (the swarm filters until rounding picks
another leader among near-ties).

Why compiled: one particle's 6-state cubature step is a few hundred flops on
6 x 6 matrices, where numpy spends its time in per-call overhead; 20 GWO
iterations of 100 wolves are 20 small array passes. Compiled, one IGWO-STCPF
step (N = 100, T_max = 20, sim/auv-sonar) costs about 1.0 ms of one core: the
cubature step 0.39 ms (~200 sin, cos, atan2, sqrt per particle), the swarm 0.25 ms
(2,000 fitness evaluations), drawing its 72,000 uniforms 0.1 ms, Python 0.2 ms
(``benchmarks/bench_002.py``). :func:`sincos_small` serves the circular means.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from replay.filters.p002.compiled_util import (
    chol_solve_rows, cubature_points, entropy_weights, factor, gram, leaders, matmul, moments, normalise, quad,
    weighted_mean, wrap)

# MODEL KERNELS: replay.filters.compiled.bind puts here the import of one model's f, h, F, H

LOG2PI = np.log(2.0 * np.pi)
U32 = 2.0**-32  # 32-bit integer u -> uniform (u + 0.5) 2^-32 in (0, 1)


@nb.njit(cache=True)
def observe(x, ph, zidx, zf, out):
    """out = the measured components ``zidx`` of h(x) (``zf`` holds the whole h(x))."""
    h(x, ph, zf)
    for a in range(zidx.shape[0]):
        out[a] = zf[zidx[a]]


@nb.njit(cache=True)
def frobenius(A, B):
    """sum(A * B) (the trace of A B') summed in index order, as ``np.sum(A * B)``, without the temporary."""
    t = 0.0
    for a in range(A.shape[0]):
        for b in range(A.shape[1]):
            t += A[a, b] * B[a, b]
    return t


@nb.njit(cache=True, nogil=True)
def cubature_step(pf, ph, X, P, L, V, logw, Z, zidx, E, Q, Qi, R, Ri, xang, zang, opts, lam, repairs, start, stop):
    """One CKF/STCKF proposal step of particles, the draw and the weight (002 §2.1–2.2).

    For the flat particle indices start .. stop - 1 (index = m N + i, run m,
    particle i), in place: X[m, i] <- m^i + L^i E[m, i] with (m^i, P^i) the
    cubature posterior given the measured components ``zidx`` of z (Z[m] holds
    them; R, R^-1, ``zang`` are theirs; ``zidx`` None: all), or the
    prediction (m^i-, P^i-) when ``Z`` is None (a predict-only step). A None
    argument gives numba a specialisation with the branch pruned, so the
    common full-measurement step carries neither the gathers nor the
    predict-only branch; P[m, i] <- P^i; L[m, i] <- its
    factor; V[m, i] (STCKF) <- the innovation average; logw[m, i] += log p(z | x)
    (0 without a measurement) + log p(x | x_prev) - log q(x); lam[m, i] <- the
    fading factor (1 for a CKF); repairs[m, i] <- covariances repaired.
    ``opts`` = [have_L, have_V, stckf, rho, beta, propagated, scale_prior,
    log det Q, log det R, nz of the model, transition]. The STCKF choices are those of
    :mod:`replay.filters.p002.stckf`. ``transition`` (the ``prior_cov`` parameter of
    :class:`replay.filters.p002.stcpf.CubatureParticleFilter`): the prediction of particle i
    is the transition density of its fixed sample, (f(x^i), Q), instead of the cubature
    prediction of (x^i, P^i) (mean f of the points, F P^i F' + Q); the propagated M of the
    fading factor is then 0 (P_k = 0), so lambda = 1 unless M is the printed H Phi H'.
    Particles are independent: callers may split the index range among threads (the
    function releases the GIL).
    """
    have_L, have_V, stckf = opts[0] != 0, opts[1] != 0, opts[2] != 0
    rho, beta, propagated, scale_prior = opts[3], opts[4], opts[5] != 0, opts[6] != 0
    logdet_Q, logdet_R, nzf, transition = opts[7], opts[8], int(opts[9]), opts[10] != 0
    M, N, n = X.shape
    nz = zang.shape[0]  # measured components (0: predict only)
    c = 2 * n
    s = np.sqrt(n)
    Y = np.empty((c, n))
    pts = np.empty((c, n))
    Dx = np.empty((c, n))
    Zc = np.empty((c, nz))
    Dz = np.empty((c, nz))
    mean, fx, mpost, xnew = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    zh, zh0, ez, y, d = np.empty(nz), np.empty(nz), np.empty(nz), np.empty(nz), np.empty(nz)
    zf, Hf = np.empty(nzf), np.empty((nzf, n))
    Lp, Lm = np.empty((n, n)), np.empty((n, n))
    Pm = np.empty((n, n))
    Fj = np.empty((n, n))
    Hj = np.empty((nz, n))
    Pxz = np.empty((n, nz))
    Pzz = np.empty((nz, nz))
    K = np.empty((n, nz))
    S = np.empty((nz, nz))
    Pn = np.empty((n, n))
    HQ, HF, HFP = np.empty((nz, n)), np.empty((nz, n)), np.empty((nz, n))
    dx = np.empty(n)
    trR = np.trace(R) if nz > 0 else 0.0
    for flat in range(start, stop):
        m, i = flat // N, flat % N
        x = X[m, i]
        f(x, pf, fx)  # f(x_prev), for p(x | x_prev)
        # --- predict (002 §2.2.1), shared by the update and the predict-only step: cubature points
        # X_j = x ± sqrt(n) L e_j through f; m- their (circular) mean; P- = 1/2n sum_j D_j D_j' + Q
        if transition:  # the fixed sample's transition density N(f(x), Q)
            mean[:] = fx
            wrap(mean, xang)
            Pm[:, :] = Q
        else:
            if have_L:
                Lp[:, :] = L[m, i]
            else:
                repairs[m, i] = factor(P[m, i], Lp)
            cubature_points(x, Lp, s, pts)
            for j in range(c):
                f(pts[j], pf, Y[j])
            moments(Y, xang, mean, Dx)
            gram(Dx, Pm)
            for a in range(n):
                for b in range(n):
                    Pm[a, b] += Q[a, b]
        g = 1.0
        if Z is None:  # predict only: the importance density is the prediction
            mpost[:] = mean
            Pn[:, :] = Pm
        else:
            z = Z[m]
            if stckf:
                F(x, pf, Fj)
            # --- update: cubature points of (m^i-, P^i-) through h ---
            repairs[m, i] += factor(Pm, Lm)
            cubature_points(mean, Lm, s, pts)
            for j in range(c):
                if zidx is None:
                    h(pts[j], ph, Zc[j])
                else:
                    observe(pts[j], ph, zidx, zf, Zc[j])
            moments(Zc, zang, zh, Dz)
            gram(Dz, Pzz)
            for a in range(n):  # P_xz = s/c L (Z_+ - Z_-)
                for b in range(nz):
                    t = 0.0
                    for j in range(n):
                        t += Lm[a, j] * (Dz[j, b] - Dz[n + j, b])
                    Pxz[a, b] = (s / c) * t
            if stckf:  # fading factor (002 §2.2.2)
                if zidx is None:
                    H(mean, ph, Hj)
                    h(mean, ph, zh0)
                else:
                    H(mean, ph, Hf)
                    for a in range(nz):
                        Hj[a] = Hf[zidx[a]]
                    observe(mean, ph, zidx, zf, zh0)
                for a in range(nz):
                    ez[a] = z[a] - zh0[a]
                wrap(ez, zang)
                for a in range(nz):
                    for b in range(nz):
                        ee = ez[a] * ez[b]
                        V[m, i, a, b] = (rho * V[m, i, a, b] + ee) / (1.0 + rho) if have_V else ee
                trN = np.trace(V[m, i]) - beta * trR
                matmul(Hj, Q, HQ)
                matmul(Hj, Fj, HF)
                trN -= frobenius(HQ, Hj)
                if propagated and transition:  # P_k = 0: nothing propagated
                    trM = 0.0
                elif propagated:  # tr(H F P F' H') = sum((H F P) * (H F))
                    matmul(HF, P[m, i], HFP)
                    trM = frobenius(HFP, HF)
                else:  # tr(H F H') as printed
                    trM = 0.0
                    for a in range(nz):
                        for b in range(n):
                            trM += HF[a, b] * Hj[a, b]
                g = max(1.0, trN / trM) if trM > 0 else 1.0
                Pzz *= g
                Pxz *= g
                if scale_prior:
                    Pm *= g
            for a in range(nz):
                for b in range(nz):
                    S[a, b] = Pzz[a, b] + R[a, b]
            chol_solve_rows(S, Pxz, K)
            for a in range(nz):
                y[a] = z[a] - zh[a]
            wrap(y, zang)
            for a in range(n):
                t = 0.0
                for b in range(nz):
                    t += K[a, b] * y[b]
                mpost[a] = mean[a] + t
            wrap(mpost, xang)
            for a in range(n):  # P = P- - P_xz K', symmetrised
                for b in range(n):
                    t = 0.0
                    for j in range(nz):
                        t += Pxz[a, j] * K[b, j]
                    Pn[a, b] = Pm[a, b] - t
            for a in range(n):
                for b in range(a):
                    Pn[a, b] = Pn[b, a] = 0.5 * (Pn[a, b] + Pn[b, a])
        lam[m, i] = g
        # --- draw x = m + L e and weight it ---
        Lq = L[m, i]
        repairs[m, i] += factor(Pn, Lq)
        e = E[m, i]
        for a in range(n):
            t = 0.0
            for b in range(a + 1):
                t += Lq[a, b] * e[b]
            xnew[a] = mpost[a] + t
        wrap(xnew, xang)
        P[m, i] = Pn
        X[m, i] = xnew
        if Z is None:
            loglik = 0.0
        else:
            if zidx is None:
                h(xnew, ph, zh0)
            else:
                observe(xnew, ph, zidx, zf, zh0)
            for a in range(nz):
                d[a] = Z[m, a] - zh0[a]
            wrap(d, zang)
            loglik = -0.5 * (quad(d, Ri) + logdet_R + nz * LOG2PI)
        for a in range(n):
            dx[a] = xnew[a] - fx[a]
        wrap(dx, xang)
        log_prior = -0.5 * (quad(dx, Qi) + logdet_Q)
        logdet_q = 0.0
        ee = 0.0
        for a in range(n):
            logdet_q += math.log(Lq[a, a])
            ee += e[a] * e[a]
        logw[m, i] += loglik + log_prior + 0.5 * (ee + 2.0 * logdet_q)


@nb.njit(cache=True, parallel=True)
def cubature_threads(pf, ph, X, P, L, V, logw, Z, zidx, E, Q, Qi, R, Ri, xang, zang, opts, lam, repairs, chunks):
    """:func:`cubature_step` over all particles, in ``chunks`` ranges run by numba's threads
    (OpenMP threads spin between steps, so waking them costs microseconds, not the ~70 us of
    a Python thread). Each particle is computed by one thread: the numbers do not depend on it."""
    total = X.shape[0] * X.shape[1]
    size = (total + chunks - 1) // chunks
    for ch in nb.prange(chunks):
        cubature_step(pf, ph, X, P, L, V, logw, Z, zidx, E, Q, Qi, R, Ri, xang, zang, opts, lam, repairs,
                      ch * size, min(total, (ch + 1) * size))


@nb.njit(cache=True)
def fitness_rows(ph, c, Xr, z, zidx, Ri, zang, xang, fx, Qi, out, skip, zf):
    """out[i] = (z - h(c + Xr[i]))' R^-1 (z - h(c + Xr[i])) for rows i not in ``skip`` (wrapped angle
    residuals; the measured components ``zidx`` of h, ``zf`` a buffer of the whole h); with ``fx``
    (N, n) (the ``fitness="posterior"`` parameter) plus the transition term
    (x - fx[i])' Q^-1 (x - fx[i]) of the particle's own ancestor, fx[i] = f(x^i_{k-1}) (``xang``
    components wrapped). ``fx`` None: the residual alone (numba prunes the branch)."""
    n, nz = Xr.shape[1], z.shape[0]
    x = np.empty(n)
    dx = np.empty(n)
    zh, d = np.empty(nz), np.empty(nz)
    for i in range(Xr.shape[0]):
        if skip[i]:
            continue
        for a in range(n):
            x[a] = c[a] + Xr[i, a]
        if zidx is None:  # all components measured (numba prunes the other branch)
            h(x, ph, zh)
        else:
            observe(x, ph, zidx, zf, zh)
        for a in range(nz):
            d[a] = z[a] - zh[a]
        wrap(d, zang)
        out[i] = quad(d, Ri)
        if fx is not None:
            for a in range(n):
                dx[a] = x[a] - fx[i, a]
            wrap(dx, xang)
            out[i] += quad(dx, Qi)


@nb.njit(cache=True, nogil=True)
def swarm_move(ph, X, logw, Z, zidx, Ri, xang, zang, movable, Fx, Qi, raw, a, improved, xi, eps, logdet_R, nzf,
               best, start, stop):
    """The relocation of :class:`replay.filters.p002.igwo_stcpf.SwarmEngine` (``estimate_at="after"``)
    for runs start .. stop - 1, in place: GWO/IGWO on the particles X (M, N, n) and their new
    log weights, log p(z | x) of the measured components ``zidx`` (Z (M, len(zidx)); R^-1 and
    ``zang`` theirs; ``nzf`` the model's nz). ``movable`` (M, n) bool: the components the wolves
    move in (None: all; the ``move_components`` parameter); ``Fx`` (M, N, n): each particle's
    f(x_{k-1}) for the posterior-type fitness with Q^-1 = ``Qi`` (None: the residual alone),
    then the new log weights are -f / 2 with that fitness.

    Per run: normalised weights from ``logw``; their weighted (circular) mean c;
    the wolves X - c (wrapped); :func:`swarm` with the uniforms ``raw`` (M,
    t_max, 2, k, N, n) as 32-bit integers (see :func:`replay.filters.p002.gwo.draws`),
    ``raw[j]`` for run ``start + j``;
    X <- c + wolves (wrapped); logw <- -(f + log det R + nz log 2 pi) / 2 with f
    the final fitness. ``best`` (M, t_max + 1) as in :func:`swarm`.
    """
    M, N, n = X.shape
    nz = Z.shape[1]
    c = np.empty(n)
    Xr = np.empty((N, n))
    f = np.empty(N)
    w = np.empty(N)
    for m in range(start, stop):
        normalise(logw[m], w)
        weighted_mean(X[m], w, xang, c)
        for i in range(N):
            for q in range(n):
                Xr[i, q] = X[m, i, q] - c[q]
            wrap(Xr[i], xang)
        mov = None if movable is None else movable[m]
        fx = None if Fx is None else Fx[m]
        swarm(ph, Xr, c, Z[m], zidx, Ri, zang, xang, mov, fx, Qi, raw[m - start], a, improved, xi, eps, f, best[m],
              nzf)
        for i in range(N):
            for q in range(n):
                X[m, i, q] = c[q] + Xr[i, q]
            wrap(X[m, i], xang)
            logw[m, i] = -0.5 * (f[i] + logdet_R + nz * LOG2PI)


@nb.njit(cache=True)
def swarm(ph, X, c, z, zidx, Ri, zang, xang, mov, fx, Qi, raw, a, improved, xi, eps, fm, best, nzf):
    """``t_max = len(a)`` GWO (``improved`` False) or IGWO iterations (002 §3.1–3.2) of one swarm, in place.

    X (N, n) are the wolves as deviations from the centre c (n,); the fitness
    of a wolf is that of :func:`fitness_rows` at c + X. ``raw`` (t_max, 2, k,
    N, n) holds the uniforms r1, r2 as 32-bit integers u, r = (u + 0.5) 2^-32;
    ``a`` the convergence factor per iteration. Outputs: fm (N,) the final
    fitness; best (t_max + 1,) the best fitness before and after each
    iteration. The leaders are not moved (elitism); the candidates are
    X_L - A |C X_L - X| with A = a (2 r1 - 1), C = 2 r2, combined with weights
    1/k (GWO) or the entropy weights of the leaders' fitness (IGWO,
    002 §3.2.2, :func:`replay.filters.p002.compiled_util.entropy_weights`). ``mov`` (n,) bool:
    only these components move (None: all); ``fx``, ``Qi``: the posterior-type fitness
    (:func:`fitness_rows`).
    """
    N, n = X.shape
    k = raw.shape[2]
    t_max = a.shape[0]
    lead = np.empty(k, np.int64)
    none = np.zeros(N, np.bool_)
    is_lead = np.zeros(N, np.bool_)
    w = np.empty(k)
    fl = np.empty(k)
    XL = np.empty((k, n))
    zf = np.empty(nzf)
    fitness_rows(ph, c, X, z, zidx, Ri, zang, xang, fx, Qi, fm, none, zf)
    best[0] = fm.min()
    for t in range(t_max):
        leaders(fm, k, lead)
        is_lead[:] = False
        for j in range(k):
            is_lead[lead[j]] = True
            fl[j] = fm[lead[j]]
            XL[j] = X[lead[j]]
        if improved:  # entropy weights (002 §3.2.2)
            entropy_weights(fl, eps, xi, w)
        else:
            w[:] = 1.0 / k
        at = a[t]
        for i in range(N):
            if is_lead[i]:
                continue
            for q in range(n):
                if mov is not None and not mov[q]:
                    continue
                acc = 0.0
                for j in range(k):
                    A = ((raw[t, 0, j, i, q] + 0.5) * U32 * 2.0 - 1.0) * at
                    Cq = (raw[t, 1, j, i, q] + 0.5) * U32 * 2.0
                    acc += w[j] * (XL[j, q] - np.abs(Cq * XL[j, q] - X[i, q]) * A)
                X[i, q] = acc
        fitness_rows(ph, c, X, z, zidx, Ri, zang, xang, fx, Qi, fm, is_lead, zf)
        best[t + 1] = fm.min()

