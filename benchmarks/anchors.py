"""Limit-style anchors for the sonar model of paper 002: the time of the arithmetic itself.

NOT PRODUCT CODE: the floor the product is measured against. The library never
imports this module, and nothing here is tested or used for results: each
anchor is the shortest compiled (numba) loop that does the arithmetic of one
filter on ``sim/auv-sonar`` (6 states ``[x, y, z, v, pitch, yaw]``, 3
measurements ``[range, elevation, azimuth]``), calling the model's own kernels
(:mod:`replay.models.auv_sonar_kernels`: ``f(x, p_f, out)``, ``h(x, p_h, out)``
with ``p_f, p_h = model.kernel_params(k)``), with every buffer allocated once
and the whole run in one compiled call. A benchmark prints ours beside it with
the ratio ours / anchor: how far the product is from what the hardware does.

Anchors:

* :func:`ukf_run`: one UKF (or CKF: other unit points) run, the step of
  :mod:`replay.filters.sigma` (points from the Cholesky factor of P, f on the
  points, circular means of the angles, wrapped deviations, P- + Q, points
  regenerated from (x-, P-), h on them, S, Pxz, gain by Cholesky solve,
  x + K y with the state angles wrapped, P - K Pxz' symmetrised, NIS);
* :func:`ekf_run`: one EKF run, the step of :mod:`replay.filters.kalman` (Joseph form) with the
  model's Jacobian kernels ``F``, ``H``;
* :func:`ukf_batch`, :func:`ekf_batch`: M such runs (``prange`` over runs): the batched
  Monte Carlo floor per run-step;
* :func:`pf_run`: a bootstrap PF with systematic resampling at every step:
  propagate with ``f`` plus pre-drawn Gaussian noise (sd from the diagonal Q),
  log-likelihood with ``h`` (wrapped angle residuals, diagonal R), normalise
  (max, exp, sum), weighted mean (circular for the angles) and covariance
  (wrapped residuals), systematic resampling from one pre-drawn uniform. The
  particles are split into a fixed number of chunks (``prange``), so the
  numbers do not depend on the thread count. The noise is drawn before the
  timed call (the floor of the arithmetic); :func:`normal_draw_ns` gives the
  cost of drawing it with NumPy's generator, which a product pays on top.
"""
from __future__ import annotations

import time

import numba as nb
import numpy as np

from replay.models import auv_sonar_kernels as K
from replay.util.kernels import cholesky as _chol  # the library's leaves: the anchor measures the step
from replay.util.kernels import point_mean as _mean  # without the Python between them
from replay.util.kernels import solve_rows as _solve

TWO_PI = 2.0 * np.pi


# --- unit points: the product's own (UKF with its defaults, CKF) ---------------------------------
def unit_points(kind, n):
    """Unit points (m, n), mean and covariance weights of the product's ``kind`` filter."""
    from replay.filters import make_filter

    return make_filter(kind).points(n)


# --- compiled pieces ---------------------------------------------------------------------------
@nb.njit(cache=True, inline="always")
def _wrap(a):
    return a - TWO_PI * np.floor(a * (1.0 / TWO_PI) + 0.5)


@nb.njit(cache=True)
def _points(x, L, xi, X, dev):
    n = x.shape[0]
    for i in range(xi.shape[0]):
        for j in range(n):
            t = 0.0
            for q in range(j + 1):
                t += xi[i, q] * L[j, q]
            dev[i, j] = t
            X[i, j] = x[j] + t


@nb.njit(cache=True)
def _ukf_run_into(x0, P0, Z, Pf, Ph, xi, wm, wc, Q, R, xmask, zmask, Xout, Pout):
    """One run; estimates into Xout (T, n), Pout (T, n, n). Returns the step where a covariance
    was not positive definite, or -1."""
    n, nz, m = x0.shape[0], R.shape[0], xi.shape[0]
    x, P = x0.copy(), P0.copy()
    L, Ls = np.zeros((n, n)), np.zeros((nz, nz))
    X, dev, Y, D = np.empty((m, n)), np.empty((m, n)), np.empty((m, n)), np.empty((m, n))
    Zs, Dz = np.empty((m, nz)), np.empty((m, nz))
    zh, y, v = np.empty(nz), np.empty(nz), np.empty(nz)
    S, Pxz, Kg = np.empty((nz, nz)), np.empty((n, nz)), np.empty((n, nz))
    for k in range(Z.shape[0]):
        # predict
        if not _chol(P, L):
            return k
        _points(x, L, xi, X, dev)
        for i in range(m):
            K.f(X[i], Pf[k], Y[i])
        _mean(Y, wm, xmask, x)
        for i in range(m):
            for j in range(n):
                d = Y[i, j] - x[j]
                D[i, j] = _wrap(d) if xmask[j] else d
        for a in range(n):
            for b in range(a + 1):
                t = Q[a, b]
                for i in range(m):
                    t += wc[i] * D[i, a] * D[i, b]
                P[a, b] = t
                P[b, a] = t
        # update: points regenerated from (x-, P-)
        if not _chol(P, L):
            return k
        _points(x, L, xi, X, dev)
        for i in range(m):
            K.h(X[i], Ph[k], Zs[i])
        _mean(Zs, wm, zmask, zh)
        for i in range(m):
            for j in range(nz):
                d = Zs[i, j] - zh[j]
                Dz[i, j] = _wrap(d) if zmask[j] else d
        for a in range(nz):
            for b in range(a + 1):
                t = R[a, b]
                for i in range(m):
                    t += wc[i] * Dz[i, a] * Dz[i, b]
                S[a, b] = t
                S[b, a] = t
        for a in range(n):
            for b in range(nz):
                t = 0.0
                for i in range(m):
                    t += wc[i] * dev[i, a] * Dz[i, b]
                Pxz[a, b] = t
        for j in range(nz):
            d = Z[k, j] - zh[j]
            y[j] = _wrap(d) if zmask[j] else d
        if not _chol(S, Ls):
            return k
        _solve(Ls, Pxz, Kg)  # K = Pxz S^-1 (the library's forward/backward substitution)
        for i in range(nz):  # NIS (kept: the product computes it)
            t = y[i]
            for q in range(i):
                t -= Ls[i, q] * v[q]
            v[i] = t / Ls[i, i]
        for i in range(n):
            t = x[i]
            for q in range(nz):
                t += Kg[i, q] * y[q]
            x[i] = _wrap(t) if xmask[i] else t
        for a in range(n):  # P - K Pxz', then symmetrised
            for b in range(n):
                t = 0.0
                for q in range(nz):
                    t += Kg[a, q] * Pxz[b, q]
                P[a, b] -= t
        for a in range(n):
            for b in range(a):
                t = 0.5 * (P[a, b] + P[b, a])
                P[a, b] = t
                P[b, a] = t
        Xout[k] = x
        Pout[k] = P
    return -1


@nb.njit(cache=True)
def ukf_run(x0, P0, Z, Pf, Ph, xi, wm, wc, Q, R, xmask, zmask, Xout, Pout):
    """The UKF/CKF anchor: one run of T = len(Z) steps in one compiled call."""
    return _ukf_run_into(x0, P0, Z, Pf, Ph, xi, wm, wc, Q, R, xmask, zmask, Xout, Pout)


@nb.njit(cache=True)
def ekf_run(x0, P0, Z, Pf, Ph, Q, R, xmask, zmask, Xout, Pout):
    """The EKF anchor (the step of :mod:`replay.filters.kalman`: F at the prior, x = f(x) with the
    angles wrapped, P = F P F' + Q; H at x-, S = H P H' + R, K = P H' S^-1, x + K y wrapped,
    Joseph form, symmetrised): one run in one compiled call. Returns -1, or the failing step."""
    n, nz = x0.shape[0], R.shape[0]
    x, P = x0.copy(), P0.copy()
    F, H, T1 = np.empty((n, n)), np.empty((nz, n)), np.empty((n, n))
    PHt, S, Ls, Kg = np.empty((n, nz)), np.empty((nz, nz)), np.zeros((nz, nz)), np.empty((n, nz))
    xp, zh, y, v, A = np.empty(n), np.empty(nz), np.empty(nz), np.empty(nz), np.empty((n, n))
    for k in range(Z.shape[0]):
        K.F(x, Pf[k], F)
        K.f(x, Pf[k], xp)
        for i in range(n):
            x[i] = _wrap(xp[i]) if xmask[i] else xp[i]
        for a in range(n):  # T1 = F P
            for b in range(n):
                t = 0.0
                for q in range(n):
                    t += F[a, q] * P[q, b]
                T1[a, b] = t
        for a in range(n):  # P = T1 F' + Q
            for b in range(n):
                t = Q[a, b]
                for q in range(n):
                    t += T1[a, q] * F[b, q]
                P[a, b] = t
        K.H(x, Ph[k], H)
        K.h(x, Ph[k], zh)
        for a in range(n):  # PHt = P H'
            for b in range(nz):
                t = 0.0
                for q in range(n):
                    t += P[a, q] * H[b, q]
                PHt[a, b] = t
        for a in range(nz):  # S = H PHt + R
            for b in range(nz):
                t = R[a, b]
                for q in range(n):
                    t += H[a, q] * PHt[q, b]
                S[a, b] = t
        for j in range(nz):
            d = Z[k, j] - zh[j]
            y[j] = _wrap(d) if zmask[j] else d
        if not _chol(S, Ls):
            return k
        _solve(Ls, PHt, Kg)  # K = PHt S^-1 (the library's forward/backward substitution)
        for i in range(nz):  # NIS
            t = y[i]
            for q in range(i):
                t -= Ls[i, q] * v[q]
            v[i] = t / Ls[i, i]
        for i in range(n):
            t = x[i]
            for q in range(nz):
                t += Kg[i, q] * y[q]
            x[i] = _wrap(t) if xmask[i] else t
        for a in range(n):  # A = I - K H
            for b in range(n):
                t = 1.0 if a == b else 0.0
                for q in range(nz):
                    t -= Kg[a, q] * H[q, b]
                A[a, b] = t
        for a in range(n):  # T1 = A P
            for b in range(n):
                t = 0.0
                for q in range(n):
                    t += A[a, q] * P[q, b]
                T1[a, b] = t
        for a in range(n):  # P = T1 A' + K R K', symmetrised
            for b in range(a + 1):
                t = 0.0
                for q in range(n):
                    t += T1[a, q] * A[b, q] + T1[b, q] * A[a, q]
                t *= 0.5
                for q in range(nz):
                    u = 0.0
                    for r in range(nz):
                        u += R[q, r] * Kg[b, r]
                    t += Kg[a, q] * u
                P[a, b] = t
                P[b, a] = t
        Xout[k] = x
        Pout[k] = P
    return -1


@nb.njit(cache=True, parallel=True)
def ukf_batch(X0, P0, Z, Pf, Ph, xi, wm, wc, Q, R, xmask, zmask, Xout, Pout, bad):
    """The batched anchor: M runs (X0 (M, n), Z (M, T, nz)), ``prange`` over the runs."""
    for r in nb.prange(X0.shape[0]):
        bad[r] = _ukf_run_into(X0[r], P0[r], Z[r], Pf, Ph, xi, wm, wc, Q, R, xmask, zmask, Xout[r], Pout[r])


@nb.njit(cache=True, parallel=True)
def ekf_batch(X0, P0, Z, Pf, Ph, Q, R, xmask, zmask, Xout, Pout, bad):
    """M EKF runs, ``prange`` over the runs."""
    for r in nb.prange(X0.shape[0]):
        bad[r] = ekf_run(X0[r], P0[r], Z[r], Pf, Ph, Q, R, xmask, zmask, Xout[r], Pout[r])


@nb.njit(cache=True, parallel=True)
def pf_run(X0, Z, Pf, Ph, sdq, inv_r, xmask, zmask, noise, offs, U, chunks, Xout, Pout):
    """The bootstrap-PF anchor: particles X0 (N, n), T = len(Z) steps, ``chunks`` fixed blocks of
    particles (``prange``); noise (>= N + max(offs), n) pre-drawn N(0, 1), U (T,) uniforms."""
    N, n = X0.shape
    nz = Z.shape[1]
    C = chunks
    X, Xn = X0.copy(), np.empty_like(X0)
    lw = np.empty(N)
    xt, yt = np.empty((C, n)), np.empty((C, nz))
    cmax, csum = np.empty(C), np.empty(C)
    part = np.empty((C, 3 * n))  # per chunk: sum w x (linear), sum w sin, sum w cos (angles)
    cov = np.empty((C, n, n))
    start, lo_i = np.empty(C), np.empty(C + 1, np.int64)
    mean = np.empty(n)
    for k in range(Z.shape[0]):
        z, pf, ph, off = Z[k], Pf[k], Ph[k], offs[k]
        for c in nb.prange(C):  # propagate, log-likelihood, local normalisation, mean partials
            lo, hi = c * N // C, (c + 1) * N // C
            mx = -np.inf
            for i in range(lo, hi):
                K.f(X[i], pf, xt[c])
                for j in range(n):
                    Xn[i, j] = xt[c, j] + sdq[j] * noise[off + i, j]
                K.h(Xn[i], ph, yt[c])
                s = 0.0
                for j in range(nz):
                    d = z[j] - yt[c, j]
                    if zmask[j]:
                        d = _wrap(d)
                    s += d * d * inv_r[j]
                lw[i] = -0.5 * s
                mx = max(mx, lw[i])
            sw = 0.0
            for j in range(3 * n):
                part[c, j] = 0.0
            for i in range(lo, hi):
                w = np.exp(lw[i] - mx)
                lw[i] = w
                sw += w
                for j in range(n):
                    if xmask[j]:
                        part[c, n + j] += w * np.sin(Xn[i, j])
                        part[c, 2 * n + j] += w * np.cos(Xn[i, j])
                    else:
                        part[c, j] += w * Xn[i, j]
            cmax[c], csum[c] = mx, sw
        g = cmax.max()
        total = 0.0
        for c in range(C):
            csum[c] *= np.exp(cmax[c] - g)
            total += csum[c]
        for j in range(n):
            a, b, t = 0.0, 0.0, 0.0
            for c in range(C):
                e = np.exp(cmax[c] - g)
                a += e * part[c, n + j]
                b += e * part[c, 2 * n + j]
                t += e * part[c, j]
            mean[j] = np.arctan2(a, b) if xmask[j] else t / total
        for c in nb.prange(C):  # covariance partials (wrapped residuals)
            lo, hi = c * N // C, (c + 1) * N // C
            sc = np.exp(cmax[c] - g) / total
            d = xt[c]
            for a in range(n):
                for b in range(a + 1):
                    cov[c, a, b] = 0.0
            for i in range(lo, hi):
                w = lw[i] * sc
                for j in range(n):
                    e = Xn[i, j] - mean[j]
                    d[j] = _wrap(e) if xmask[j] else e
                for a in range(n):
                    wa = w * d[a]
                    for b in range(a + 1):
                        cov[c, a, b] += wa * d[b]
        for a in range(n):
            for b in range(a + 1):
                t = 0.0
                for c in range(C):
                    t += cov[c, a, b]
                Pout[k, a, b] = t
                Pout[k, b, a] = t
            Xout[k, a] = mean[a]
        # systematic resampling: positions (U[k] + i) / N; chunk c holds [start_c, start_c + W_c)
        acc = 0.0
        lo_i[0] = 0
        for c in range(C):
            start[c] = acc
            acc += csum[c] / total
            if c > 0:
                lo_i[c] = min(N, max(lo_i[c - 1], int(np.ceil(start[c] * N - U[k]))))
        lo_i[C] = N
        for c in nb.prange(C):
            lo, hi = c * N // C, (c + 1) * N // C
            sc = np.exp(cmax[c] - g) / total
            j = lo
            cw = start[c] + lw[j] * sc
            for i in range(lo_i[c], lo_i[c + 1]):
                u = (U[k] + i) / N
                while u >= cw and j < hi - 1:
                    j += 1
                    cw += lw[j] * sc
                for q in range(n):
                    X[i, q] = Xn[j, q]
    return X


# --- Python side: the sonar problem's arrays, timing --------------------------------------------
def arrays(pb, steps=None):
    """The anchors' inputs from a product problem ``pb`` (``make_task('sonar').build(...)``)."""
    model = pb.model
    T = len(pb.z) if steps is None else min(steps, len(pb.z))
    params = [model.kernel_params(k) for k in range(T)]
    Q, R = np.asarray(model.Q, float), np.asarray(model.R, float)
    xmask, zmask = np.zeros(model.nx, np.bool_), np.zeros(model.nz, np.bool_)
    xmask[list(model.x_angles)] = True
    zmask[list(model.z_angles)] = True
    return {"Z": np.ascontiguousarray(pb.z[:T], float), "Pf": np.array([p[0] for p in params], float),
            "Ph": np.array([p[1] for p in params], float), "Q": Q, "R": R, "xmask": xmask, "zmask": zmask,
            "x0": np.asarray(pb.x0, float), "P0": np.asarray(pb.P0, float)}


def _best(fn, repeat):
    fn()  # warm-up (compiles or loads from the cache)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def time_kalman(pb, kind="ukf", repeat=20):
    """Seconds per step of the UKF (``kind="ckf"``: CKF, ``"ekf"``: EKF) anchor on one run, and its
    estimates."""
    a = arrays(pb)
    T, n = a["Z"].shape[0], len(a["x0"])
    X, P = np.full((T, n), np.nan), np.full((T, n, n), np.nan)
    if kind == "ekf":
        def run():
            ekf_run(a["x0"], a["P0"], a["Z"], a["Pf"], a["Ph"], a["Q"], a["R"], a["xmask"], a["zmask"], X, P)
            return X

        best, X = _best(run, repeat)
        return best / T, X
    xi, wm, wc = unit_points(kind, n)

    def run():
        ukf_run(a["x0"], a["P0"], a["Z"], a["Pf"], a["Ph"], xi, wm, wc, a["Q"], a["R"], a["xmask"], a["zmask"], X, P)
        return X

    best, X = _best(run, repeat)
    return best / T, X


def time_batch(pbs, kind="ukf", repeat=5, steps=None):
    """Seconds per run-step of the batched anchor (``kind``: ukf, ckf or ekf) on the first ``steps``
    steps of the problems ``pbs`` (one model), on the threads numba has now (:func:`gauge.threads`)."""
    a = arrays(pbs[0], steps)
    T = a["Z"].shape[0]
    X0 = np.stack([p.x0 for p in pbs]).astype(float)
    P0 = np.stack([p.P0 for p in pbs]).astype(float)
    Z = np.ascontiguousarray(np.stack([p.z[:T] for p in pbs]), float)
    M, T, n = len(pbs), Z.shape[1], X0.shape[1]
    X, P, bad = np.full((M, T, n), np.nan), np.full((M, T, n, n), np.nan), np.empty(M, np.int64)
    if kind == "ekf":
        def run():
            ekf_batch(X0, P0, Z, a["Pf"], a["Ph"], a["Q"], a["R"], a["xmask"], a["zmask"], X, P, bad)
            return X

        best, X = _best(run, repeat)
        return best / (M * T), X
    xi, wm, wc = unit_points(kind, n)

    def run():
        ukf_batch(X0, P0, Z, a["Pf"], a["Ph"], xi, wm, wc, a["Q"], a["R"], a["xmask"], a["zmask"], X, P, bad)
        return X

    best, X = _best(run, repeat)
    return best / (M * T), X


def pf_chunks(N: int) -> int:
    """Fixed blocks of particles: one below 2048 particles, else a power of two near N / 1024 (<= 64),
    independent of the thread count."""
    if N < 2048:
        return 1
    return int(min(64, 2 ** int(np.log2(N / 1024))))


def pf_inputs(pb, N, steps=None, seed=0):
    """Initial particles, noise, offsets and uniforms of the PF anchor (drawn here, not timed)."""
    a = arrays(pb, steps)
    T, n = a["Z"].shape[0], len(a["x0"])
    g = np.random.default_rng(seed)
    X0 = a["x0"] + g.standard_normal((N, n)) @ np.linalg.cholesky(a["P0"]).T
    Q, R = a["Q"], a["R"]
    if np.count_nonzero(Q - np.diag(np.diag(Q))) or np.count_nonzero(R - np.diag(np.diag(R))):
        raise ValueError("anchors.pf_run: Q and R must be diagonal (the sonar model's are)")
    noise = g.standard_normal((2 * N, n))
    return {**a, "X0": X0, "sdq": np.sqrt(np.diag(Q)), "inv_r": 1.0 / np.diag(R), "noise": noise,
            "offs": g.integers(0, N, T), "U": g.random(T), "T": T, "n": n}


def time_pf(pb, N, steps=None, repeat=3, seed=0):
    """Seconds per particle-step of the PF anchor with N particles over ``steps`` steps, on the
    threads numba has now (:func:`gauge.threads`; one below 2048 particles: a single block); and its
    estimates (T, n)."""
    d = pf_inputs(pb, N, steps, seed)
    T, n = d["T"], d["n"]
    X, P = np.full((T, n), np.nan), np.full((T, n, n), np.nan)
    C = pf_chunks(N)

    def run():
        pf_run(d["X0"], d["Z"], d["Pf"], d["Ph"], d["sdq"], d["inv_r"], d["xmask"], d["zmask"], d["noise"],
               d["offs"], d["U"], C, X, P)
        return X.copy()

    threads = nb.get_num_threads()
    if C == 1:  # one block of particles: nothing to share, so no thread waits at the barriers
        nb.set_num_threads(1)
    try:
        best, X = _best(run, repeat)
    finally:
        nb.set_num_threads(threads)
    return best / (N * T), X


def normal_draw_ns(N, nx=6, repeat=5):
    """Nanoseconds per particle to draw ``nx`` standard normals with NumPy's default generator
    (``Generator.standard_normal((N, nx))``): what drawing the process noise adds to the floor."""
    g = np.random.default_rng(0)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        g.standard_normal((N, nx))
        best = min(best, time.perf_counter() - t0)
    return best / N * 1e9


def ratio(ours, anchor):
    """ours / anchor, or NaN."""
    try:
        return ours / anchor if anchor > 0 else float("nan")
    except TypeError:
        return float("nan")
