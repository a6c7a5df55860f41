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
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np

from replay.filters.p002.compiled_util import (
    Fading,
    Fit,
    Noise,
    Particles,
    Proposal,
    copy1,
    copy2,
    correct,
    cubature_points,
    draw,
    factor,
    fading_factor,
    gram,
    moments,
    normalise,
    quad,
    weighted_mean,
    workspace,
    wrap,
)
from replay.filters.p002.swarm_kernels import entropy_weights, leaders
from replay.util.kernels import LOG_2PI, gauss_logpdf

# MODEL KERNELS: replay.filters.compiled.bind puts here the import of one model's f, h, F, H

U32 = 2.0**-32  # 32-bit integer u -> uniform (u + 0.5) 2^-32 in (0, 1)


@nb.njit(cache=True)
def observe(x, ph, zidx, zf, out):
    """out = the measured components ``zidx`` of h(x) (``zf`` holds the whole h(x))."""
    h(x, ph, zf)
    for a in range(zidx.shape[0]):
        out[a] = zf[zidx[a]]


@nb.njit(cache=True)
def maha(x, ph, z, zidx, zang, Ri, zf, zh, d):
    """d' R^-1 d of the residual d = z - h(x) (angles wrapped) of the measured components ``zidx``
    of h (None: all; ``zf`` a buffer of the whole h); zh, d work arrays of z's size."""
    if zidx is None:
        h(x, ph, zh)
    else:
        observe(x, ph, zidx, zf, zh)
    for a in range(z.shape[0]):
        d[a] = z[a] - zh[a]
    wrap(d, zang)
    return quad(d, Ri)


@nb.njit(cache=True)
def predict(x, pf, Q, xang, w):
    """The cubature prediction (002 §2.2.1) of (x, L L') with L = w.Lp: points X_j = x +- sqrt(n) L e_j
    through f, w.mean their (circular) mean, w.Pm = 1/2n sum_j D_j D_j' + Q."""
    n = x.shape[0]
    cubature_points(x, w.Lp, np.sqrt(n), w.pts)
    for j in range(2 * n):
        f(w.pts[j], pf, w.Y[j])
    moments(w.Y, xang, w.mean, w.Dx)
    gram(w.Dx, w.Pm)
    for a in range(n):
        for b in range(n):
            w.Pm[a, b] += Q[a, b]


@nb.njit(cache=True)
def innovation(ph, zidx, zang, w):
    """The cubature innovation moments of the prediction (w.mean, w.Pm): points through h (the
    measured components ``zidx``), w.zh their (circular) mean, w.Pzz = 1/2n sum_j D_j D_j' and
    w.Pxz = sqrt(n)/2n L (D_+ - D_-). Returns 1 when w.Pm had to be repaired to be factored."""
    n, nz = w.Pxz.shape
    s = np.sqrt(n)
    repaired = factor(w.Pm, w.Lm)
    cubature_points(w.mean, w.Lm, s, w.pts)
    for j in range(2 * n):
        if zidx is None:
            h(w.pts[j], ph, w.Zc[j])
        else:
            observe(w.pts[j], ph, zidx, w.zf, w.Zc[j])
    moments(w.Zc, zang, w.zh, w.Dz)
    gram(w.Dz, w.Pzz)
    for a in range(n):
        for b in range(nz):
            t = 0.0
            for j in range(n):
                t += w.Lm[a, j] * (w.Dz[j, b] - w.Dz[n + j, b])
            w.Pxz[a, b] = (s / (2 * n)) * t
    return repaired


@nb.njit(cache=True)
def particle_fading(x, z, pf, ph, zidx, prev, noise, st, w):
    """One particle's fading factor (:func:`replay.filters.p002.compiled_util.fading_factor`): F at its
    previous state x (covariance P), H and h at its prediction w.mean, e = z - h (wrapped);
    ``prev`` = (P, V, fresh), its innovation average V (``fresh``: restarted); Q, R and the angle
    flags of ``noise`` (a :data:`replay.filters.p002.compiled_util.Noise`)."""
    P, V, fresh = prev
    F(x, pf, w.Fj)
    if zidx is None:
        H(w.mean, ph, w.Hj)
        h(w.mean, ph, w.zh0)
    else:
        H(w.mean, ph, w.Hf)
        for a in range(zidx.shape[0]):
            copy1(w.Hj[a], w.Hf[zidx[a]])
        observe(w.mean, ph, zidx, w.zf, w.zh0)
    for a in range(z.shape[0]):
        w.ez[a] = z[a] - w.zh0[a]
    wrap(w.ez, noise.zang)
    return fading_factor(V, w.ez, fresh, w.Hj, w.Fj, P, noise.Q, noise.R, st, (w.HQ, w.HF, w.HFP))


@nb.njit(cache=True, nogil=True)
def cubature_step(pf, ph, parts, Z, zidx, E, noise, pr, start, stop):
    """One CKF/STCKF proposal step of particles, the draw and the weight (002 §2.1–2.2).

    ``parts`` the particles' arrays (:data:`replay.filters.p002.compiled_util.Particles`: X, P, L,
    V, logw, lam, repairs), ``noise`` Q, R and their inverses, the angle flags
    (:data:`~replay.filters.p002.compiled_util.Noise`). For the flat particle indices start ..
    stop - 1 (index = m N + i, run m, particle i), in
    place: X[m, i] <- m^i + L^i E[m, i] with (m^i, P^i) the cubature posterior given the measured
    components ``zidx`` of z (Z[m] holds them; R, R^-1, ``zang`` are theirs; ``zidx`` None: all),
    or the prediction (m^i-, P^i-) when ``Z`` is None (a predict-only step; a None argument gives
    numba a specialisation with the branch pruned); P[m, i] <- P^i; L[m, i] <- its factor;
    V[m, i] (STCKF) <- the innovation average; logw[m, i] += log p(z | x) (0 without a
    measurement) + log p(x | x_prev) - log q(x); lam[m, i] <- the fading factor (1 for a CKF);
    repairs[m, i] <- covariances repaired. ``pr``: a :class:`replay.filters.p002.compiled_util.Proposal`
    (the STCKF choices are those of :mod:`replay.filters.p002.stckf`). With ``pr.transition``
    (the ``prior_cov`` parameter) the prediction of particle i is the transition density of its
    fixed sample, (f(x^i), Q), instead of the cubature prediction of (x^i, P^i); the fading
    factor then propagates P_k = 0. Particles are independent: callers may split the index
    range among threads (the function releases the GIL).
    """
    X, P, L, V, logw, lam, repairs = parts
    Q, Qi, R, Ri, xang, zang = noise
    M, N, n = X.shape
    nz = zang.shape[0]  # measured components (0: predict only)
    w = workspace(n, nz, pr.nzf)
    nothing = np.zeros((n, n))  # the P_k of a transition-density prediction
    for flat in range(start, stop):
        m, i = flat // N, flat % N
        x = X[m, i]
        f(x, pf, w.fx)  # f(x_prev), for p(x | x_prev)
        if pr.transition:  # the fixed sample's transition density N(f(x), Q)
            copy1(w.mean, w.fx)
            wrap(w.mean, xang)
            copy2(w.Pm, Q)
        else:
            if pr.have_L:
                copy2(w.Lp, L[m, i])
            else:
                repairs[m, i] = factor(P[m, i], w.Lp)
            predict(x, pf, Q, xang, w)
        g = 1.0
        if Z is None:  # predict only: the importance density is the prediction
            copy1(w.mpost, w.mean)
            copy2(w.Pn, w.Pm)
        else:
            repairs[m, i] += innovation(ph, zidx, zang, w)
            if pr.stckf:  # fading factor (002 §2.2.2)
                prev = (nothing if pr.transition else P[m, i], V[m, i], not pr.have_V)
                g = particle_fading(x, Z[m], pf, ph, zidx, prev, noise, pr.fading, w)
                Pzz, Pxz, Pm = w.Pzz, w.Pxz, w.Pm
                Pzz *= g
                Pxz *= g
                if pr.scale_prior:
                    Pm *= g
            correct(Z[m], R, zang, xang, w)
        lam[m, i] = g
        repairs[m, i] += draw(w.mpost, w.Pn, E[m, i], L[m, i], xang, w.xnew)  # x = m + L e
        copy2(P[m, i], w.Pn)
        copy1(X[m, i], w.xnew)
        loglik = 0.0
        if Z is not None:
            loglik = gauss_logpdf(maha(w.xnew, ph, Z[m], zidx, zang, Ri, w.zf, w.zh0, w.d) + pr.logdet_R, nz * LOG_2PI)
        for a in range(n):
            w.dx[a] = w.xnew[a] - w.fx[a]
        wrap(w.dx, xang)
        log_prior = gauss_logpdf(quad(w.dx, Qi), pr.logdet_Q)  # the n log 2 pi cancel in the ratio
        logdet_q = 0.0
        ee = 0.0
        for a in range(n):
            logdet_q += math.log(L[m, i, a, a])
            ee += E[m, i, a] * E[m, i, a]
        logw[m, i] += loglik + log_prior - gauss_logpdf(ee, 2.0 * logdet_q)


@nb.njit(cache=True, parallel=True)
def cubature_threads(pf, ph, parts, Z, zidx, E, noise, pr, chunks):
    """:func:`cubature_step` over all particles, in ``chunks`` ranges run by numba's threads
    (OpenMP threads spin between steps, so waking them costs microseconds, not the ~70 us of
    a Python thread). Each particle is computed by one thread: the numbers do not depend on it.
    The records ``parts``, ``noise`` and ``pr`` enter the threads as their fields (numba passes no
    tuple record into them)."""
    X, P, L, V, logw, lam, repairs = parts
    Q, Qi, R, Ri, xang, zang = noise
    total = X.shape[0] * X.shape[1]
    size = (total + chunks - 1) // chunks
    rho, beta, propagated = pr.fading.rho, pr.fading.beta, pr.fading.propagated
    stckf, scale, transition, have_L, have_V = pr.stckf, pr.scale_prior, pr.transition, pr.have_L, pr.have_V
    logdet_Q, logdet_R, nzf = pr.logdet_Q, pr.logdet_R, pr.nzf
    for ch in nb.prange(chunks):
        rec = Proposal(stckf, Fading(rho, beta, propagated), scale, transition, have_L, have_V, logdet_Q, logdet_R, nzf)
        parts_ch = Particles(X, P, L, V, logw, lam, repairs)
        noise_ch = Noise(Q, Qi, R, Ri, xang, zang)
        cubature_step(pf, ph, parts_ch, Z, zidx, E, noise_ch, rec, ch * size, min(total, (ch + 1) * size))


@nb.njit(cache=True)
def fitness_rows(ph, c, Xr, fit, zidx, post, out, skip, zf):
    """out[i] = (z - h(c + Xr[i]))' R^-1 (z - h(c + Xr[i])) for rows i not in ``skip`` (z, R^-1 and
    the angle flags from ``fit``, a :data:`replay.filters.p002.compiled_util.Fit`; wrapped angle
    residuals; the measured components ``zidx`` of h, ``zf`` a buffer of the whole h); with ``post``
    = (fx (N, n), Q^-1) (the ``fitness="posterior"`` parameter) plus the transition term
    (x - fx[i])' Q^-1 (x - fx[i]) of the particle's own ancestor, fx[i] = f(x^i_{k-1}) (``xang``
    components wrapped). ``post`` None: the residual alone (numba prunes the branch)."""
    z, Ri, zang, xang = fit.z, fit.Ri, fit.zang, fit.xang
    n, nz = Xr.shape[1], z.shape[0]
    x = np.empty(n)
    dx = np.empty(n)
    zh, d = np.empty(nz), np.empty(nz)
    for i in range(Xr.shape[0]):
        if skip[i]:
            continue
        for a in range(n):
            x[a] = c[a] + Xr[i, a]
        out[i] = maha(x, ph, z, zidx, zang, Ri, zf, zh, d)
        if post is not None:
            fx, Qi = post
            for a in range(n):
                dx[a] = x[a] - fx[i, a]
            wrap(dx, xang)
            out[i] += quad(dx, Qi)


@nb.njit(cache=True, nogil=True)
def swarm_move(ph, X, logw, fit, zidx, movable, post, raw, search, span):
    """The relocation of :class:`replay.filters.p002.igwo_stcpf.SwarmEngine` (``estimate_at="after"``)
    for runs ``span`` = (start, stop): start .. stop - 1, in place: GWO/IGWO (``search`` = (settings,
    a :data:`replay.filters.p002.compiled_util.Gwo`; ``best``)) on the particles X (M, N, n)
    and their new log weights, log p(z | x) of the measured components ``zidx`` (``fit``, a
    :data:`~replay.filters.p002.compiled_util.Fit`: Z (M, len(zidx)); R^-1 and ``zang`` theirs;
    ``nzf`` the model's nz). ``movable`` (M, n) bool: the components the wolves
    move in (None: all; the ``move_components`` parameter); ``post`` = (Fx (M, N, n), Q^-1): each
    particle's f(x_{k-1}) for the posterior-type fitness (None: the residual alone),
    then the new log weights are -f / 2 with that fitness.

    Per run: normalised weights from ``logw``; their weighted (circular) mean c;
    the wolves X - c (wrapped); :func:`swarm` with the uniforms ``raw`` (M,
    t_max, 2, k, N, n) as 32-bit integers (see :func:`replay.filters.p002.gwo.draws`),
    ``raw[j]`` for run ``start + j``;
    X <- c + wolves (wrapped); logw <- -(f + log det R + nz log 2 pi) / 2 with f
    the final fitness. ``best`` (M, t_max + 1) as in :func:`swarm`.
    """
    gwo, best = search
    start, stop = span
    xang = fit.xang
    M, N, n = X.shape
    nz = fit.z.shape[1]
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
        pm = None if post is None else (post[0][m], post[1])
        fm = Fit(fit.z[m], fit.Ri, fit.zang, fit.xang, fit.logdet_R, fit.nzf)
        swarm(ph, Xr, c, fm, zidx, mov, pm, raw[m - start], gwo, (f, best[m]))
        for i in range(N):
            for q in range(n):
                X[m, i, q] = c[q] + Xr[i, q]
            wrap(X[m, i], xang)
            logw[m, i] = gauss_logpdf(f[i] + fit.logdet_R, nz * LOG_2PI)


@nb.njit(cache=True)
def swarm(ph, X, c, fit, zidx, mov, post, raw, gwo, out):
    """``t_max = len(a)`` GWO (``improved`` False) or IGWO iterations (002 §3.1–3.2) of one swarm, in place.

    X (N, n) are the wolves as deviations from the centre c (n,); the fitness
    of a wolf is that of :func:`fitness_rows` at c + X. ``raw`` (t_max, 2, k,
    N, n) holds the uniforms r1, r2 as 32-bit integers u, r = (u + 0.5) 2^-32;
    ``a`` the convergence factor per iteration. Outputs: fm (N,) the final
    fitness; best (t_max + 1,) the best fitness before and after each
    iteration (``out`` = (fm, best)). The leaders are not moved (elitism); the candidates are
    X_L - A |C X_L - X| with A = a (2 r1 - 1), C = 2 r2, combined with weights
    1/k (GWO) or the entropy weights of the leaders' fitness (IGWO,
    002 §3.2.2, :func:`replay.filters.p002.swarm_kernels.entropy_weights`). ``mov`` (n,) bool:
    only these components move (None: all); ``fit`` (its z one row), ``post``: the fitness
    (:func:`fitness_rows`); ``gwo``: ``a``, ``improved``, the entropy weights' ``xi`` and ``eps``.
    """
    a, improved, xi, eps = gwo
    fm, best = out
    N, n = X.shape
    k = raw.shape[2]
    t_max = a.shape[0]
    lead = np.empty(k, np.int64)
    none = np.zeros(N, np.bool_)
    is_lead = np.zeros(N, np.bool_)
    w = np.empty(k)
    fl = np.empty(k)
    XL = np.empty((k, n))
    zf = np.empty(fit.nzf)
    fitness_rows(ph, c, X, fit, zidx, post, fm, none, zf)
    best[0] = fm.min()
    for t in range(t_max):
        leaders(fm, k, lead)
        is_lead[:] = False
        for j in range(k):
            is_lead[lead[j]] = True
            fl[j] = fm[lead[j]]
            copy1(XL[j], X[lead[j]])
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
        fitness_rows(ph, c, X, fit, zidx, post, fm, is_lead, zf)
        best[t + 1] = fm.min()
