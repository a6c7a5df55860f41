"""The bootstrap PF's whole run in one compiled loop: the steps of :class:`replay.filters.pf.PFEngine`.

For one run, every step k (module docstring of :mod:`replay.filters.pf`)::

    propagate   x^i <- f(x^i) + sd * e^i,   e^i ~ N(0, I) from the run's generator   (particles.perturb)
    weight      l^i <- l^i + log N(z_k; h(x^i), R_k)        (replay.util.kernels.gauss_loglik; the
                components measured at k only, R_k restricted to them)
    (optimal proposal, ``opt``: both at once, particles.propose: drawn from the Kalman update of
    f(x^i) by z_k, l^i <- l^i + log N(z_k; sign f(x^i), sign^2 Q + R_k), the measured components only)
    normalise   w, l <- particles.weights(l)                   (log domain)
    estimate    x_k, P_k <- particles.moments(x, w)          (circular means for angles)
    resample    when ESS = 1 / sum w^2 < threshold * N (particles.ess_rows): systematic
                (resampling.invert_sorted), then roughening (particles.roughen) when K > 0

The same kernels as the step-by-step engine, and the same draws from the same
``numpy.random.Generator`` in the same order (numba draws from a NumPy
generator with NumPy's own algorithms, sharing its state): the loop gives the
numbers of the steps bit for bit, and leaves the generator where the steps
leave it (``tests/test_pf_loop.py``). Q and R may change from step to step
(:func:`replay.filters.compiled.cov_stacks`) and any component may be missing at a step (the
fusion task's sensors: each message measures a few components); the factors of R are those
``Model.loglik`` takes (``noise_factor``), made once per distinct pattern and R before the loop.
The steps remain the readable reference and the general path: models that draw their own
noise or weigh their own likelihood, a non-diagonal Q, gated measurements
(:mod:`replay.filters.gating`), other resampling schemes and subclasses
that change the weighting all step in Python.
"""

from __future__ import annotations

from collections import namedtuple
from time import perf_counter

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np
from numba import types

from replay.model import Model, noise_factor
from replay.util.angles import angle_mask
from replay.util.kernels import LOG_2PI, gauss_loglik

from .compiled import ROWS_KERNEL, bound, cov_stacks, derived_from_kernels, grain, loop_ready
from .compiled import measured_steps, param_stacks, row_kernels, split
from .particles import ess_rows, moments, perturb, propose, roughen, weights
from .resampling import SCHEMES, invert_sorted, systematic

# particle-steps from which the missing loop is compiled (~2 s, once per machine; it saves
# 0.2-0.3 µs per particle-step against the steps: their Python and numpy calls per run and step)
COMPILE_AT = 10_000_000
# :func:`pf_run`'s arguments that travel together (namedtuples: numba unpacks them at no cost)
Cloud = namedtuple("Cloud", "X logw w")  # the particles (N, n), their log-weights and weights (N,)
Obs = namedtuple("Obs", "Z sel mask fac rdiag rL rinv rconst")  # the measurements, the components measured
# at each step, their angle flags and the factors of R (:func:`likelihood_factors`)
Params = namedtuple("Params", "Pf Ph qsd sd0")  # per step: the kernels' parameters, the process noise's sd
Proposal = namedtuple("Proposal", "opt sidx ssgn rvar")  # the optimal proposal (``opt``) and its arrays
Resampling = namedtuple("Resampling", "limit rough logw0")  # threshold * N, roughening K, -log N
Out = namedtuple("Out", "X P ess")  # the estimates written: (steps, n), (steps, n, n), ESS (steps,)


@nb.njit(cache=True, nogil=True)
def pf_run(f, h, g, cloud, obs, par, prop, rs, xmask, out):
    """Every step of one run of the bootstrap PF (module docstring). ``cloud`` (:data:`Cloud`): X
    (N, n) particles, logw and w (N,) their log-weights and weights (all changed in place); ``obs``
    (:data:`Obs`): Z (steps, nz); ``sel[k] = [d, i_0 .. i_{d-1}]`` the components measured at step
    k (:func:`replay.filters.compiled.measured_steps`; d = 0: no weighting at k); their angle flags
    ``mask``; R of the measured components at step k as ``gauss_loglik`` takes it: entry u = fac[k]
    of rdiag (U,), rL (U, nz, nz), rinv (U, nz), rconst (U,) (its top-left d x d, first d); ``par``
    (:data:`Params`): Pf[k], Ph[k] the kernels' parameters; qsd[k] the process noise's standard
    deviations (n,) (a stack of one: the same at every step); ``sd0`` the first step's spread
    (qsd[0], or the prior's with it: PFEngine.start); ``prop`` (:data:`Proposal`): ``opt``, the
    optimal proposal of the selection ``sidx``, ``ssgn`` with R's variances ``rvar`` (a stack);
    ``rs`` (:data:`Resampling`): ``limit`` = threshold * N, roughening constant ``rough`` = K,
    ``logw0`` = -log N. Writes ``out`` (:data:`Out`): X (steps, n), P (steps, n, n) and ess
    (steps,), the ESS before resampling. Returns the number of resampling steps."""
    X, logw, w = cloud
    Z, sel, zmask, fac, rdiag, rL, rinv, rconst = obs
    Pf, Ph, qsd, sd0 = par
    opt, sidx, ssgn, rvar = prop
    limit, rough, logw0 = rs
    Xout, Pout, ess = out
    N, n = X.shape
    steps, nz = Z.shape
    Y, zh, ll = np.empty((N, n)), np.empty((N, nz)), np.empty(N)
    wz, z, zm = np.empty(N * nz), np.empty(nz), np.empty(nz, np.bool_)
    a, e1 = np.empty(N, np.int64), np.empty(1)
    count = 0
    for k in range(steps):
        f(X, Pf[k], Y)  # propagate: f on every particle, then the noise
        sdk = sd0 if k == 0 else qsd[k % qsd.shape[0]]
        if opt:  # the optimal proposal: moved and drawn given z_k, ll its predictive likelihood
            propose(Y, sdk, Z[k], sel[k], sidx, ssgn, rvar[k % rvar.shape[0]], zmask, ll, g)
        else:
            perturb(Y, sdk, g)
        X, Y = Y, X
        d = sel[k, 0]
        if d > 0 and opt:
            for i in range(N):
                logw[i] += ll[i]
            weights(logw, w)
        elif d > 0:  # weight (no measurement: the weights stay)
            h(X, Ph[k], zh)
            u = fac[k]
            if d == nz:  # every component: the arrays as they are
                gauss_loglik(zh, Z[k], zmask, rdiag[u], rL[u], rinv[u], rconst[u], ll)
            else:  # the measured components
                zc = wz[: N * d].reshape((N, d))
                for q in range(d):
                    s = sel[k, 1 + q]
                    z[q], zm[q] = Z[k, s], zmask[s]
                    for i in range(N):
                        zc[i, q] = zh[i, s]
                gauss_loglik(zc, z[:d], zm[:d], rdiag[u], rL[u, :d, :d], rinv[u, :d], rconst[u], ll)
            for i in range(N):
                logw[i] += ll[i]
            weights(logw, w)
        moments(X, w, xmask, Xout[k], Pout[k])  # estimate before resampling
        ess_rows(w.reshape((1, N)), e1)
        ess[k] = e1[0]
        if e1[0] < limit:  # resample (ESS below the threshold)
            invert_sorted(w, g.random(), a)
            for i in range(N):
                for q in range(n):
                    Y[i, q] = X[a[i], q]
            X, Y = Y, X
            if rough > 0.0:
                roughen(X, rough, g)
            for i in range(N):
                w[i] = 1.0 / N
                logw[i] = logw0
            count += 1
    return count


_GEN = nb.typeof(np.random.default_rng(0))
_V, _M, _M3 = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1]
_I2 = types.int64[:, ::1]
_record = types.BaseTuple.from_types  # the numba type of a namedtuple of these field types
_MASK, _INDEX = types.boolean[::1], types.int64[::1]
PF_RUN = types.int64(
    ROWS_KERNEL,
    ROWS_KERNEL,
    _GEN,
    _record((_M, _V, _V), Cloud),
    _record((_M, _I2, _MASK, _INDEX, _MASK, _M3, _M, _V), Obs),
    _record((_M, _M, _M, _V), Params),
    _record((types.boolean, _INDEX, _V, _M), Proposal),
    _record((types.float64,) * 3, Resampling),
    _MASK,
    _record((_M, _M3, _V), Out),
)


def run(engine, Z, finite):
    """Every step of the engine's runs (:meth:`replay.filters.pf.PFEngine.run_all`): ``(X, P,
    nis, dof)`` stacks, or None when the loop does not apply (module docstring; also a generator
    that is not a ``numpy.random.Generator``) or is not compiled and the
    job is smaller than ``COMPILE_AT`` particle-steps. The particles are the
    engine's, the runs' generators advance as the steps would advance them."""
    m, flt = engine.model, engine.flt
    M, steps, nz = Z.shape
    N = flt.n_particles
    if (
        not applies(engine, m)
        or not all(isinstance(g, np.random.Generator) for g in engine.active)
        or not loop_ready(pf_run, PF_RUN, M * steps * N >= COMPILE_AT, M * steps * N, COMPILE_AT)
    ):
        return None
    stacks, covs = param_stacks(m, steps), cov_stacks(m, steps)
    if stacks is None or covs is None:
        return None
    qsd = process_sd(covs[0])
    sels, factors = [], {}
    for j in range(M):  # runs measuring the same components share their factors of R
        key = finite[j].tobytes()
        if key not in factors:
            factors[key] = likelihood_factors(covs[1], finite[j])
        sels.append(factors[key])
    if qsd is None or any(f is None for f in factors.values()):  # a covariance without a factor, a
        return None  # non-diagonal Q: the steps meet it (and record a divergence) or draw it
    call = bound(pf_run, *row_kernels(m, (0, 1)))
    xmask, zmask = np.array(angle_mask(m.x_angles, m.nx)), np.array(angle_mask(m.z_angles, nz))
    X, P, E = np.empty((M, steps, m.nx)), np.empty((M, steps, m.nx, m.nx)), np.empty((M, steps))
    Z = np.ascontiguousarray(Z, dtype=float)
    opt = bool(engine.optimal)
    sidx, ssgn = selection(m) if opt else (np.zeros(0, np.int64), np.zeros(0))
    rvar = np.ascontiguousarray(np.diagonal(covs[1], axis1=1, axis2=2)) if opt else np.zeros((1, nz))
    prop = Proposal(opt, sidx, ssgn, rvar)
    rs = Resampling(float(flt.ess_threshold * N), float(flt.roughening), float(engine.logw0))

    def runs(lo, hi):  # each run from its own generator: the same numbers on any thread (~0.15 µs
        # a particle-step)
        return [
            call(
                engine.active[j],
                Cloud(*(np.ascontiguousarray(a[j]) for a in (engine.X, engine.logw, engine.w))),
                Obs(Z[j], sels[j][0], zmask, *sels[j][1:]),
                Params(*stacks, qsd, qsd[0] if engine.sd0 is None else np.ascontiguousarray(engine.sd0[j])),
                prop,
                rs,
                xmask,
                Out(X[j], P[j], E[j]),
            )
            for j in range(lo, hi)
        ]

    t0 = perf_counter()
    counts = [c for part in split(runs, M, grain=grain(0.15 * steps * N)) for c in part]
    engine.seconds = perf_counter() - t0  # the computation, without loading the compiled code
    for j, c in enumerate(counts):
        engine.resampled[engine.ids[j]] += c
        if steps:  # summed in step order, as the steps sum it
            engine.ess_sum[engine.ids[j]] += np.cumsum(E[j])[-1]
            engine.ess_steps[engine.ids[j]] += steps
    return X, P, np.full((M, steps), np.nan), np.zeros((M, steps), int)


def selection(model):
    """``(index, sign)`` float/int arrays of a model whose h selects state components
    (``model.selection()``), else None."""
    sel = getattr(model, "selection", None)
    if sel is None:
        return None
    index, sign = sel()
    return np.asarray(index, np.int64), np.asarray(sign, float)


def process_sd(Q):
    """The standard deviations (S, n) of a stack of diagonal process noise covariances Q (S, n, n)
    (``noise_factor``'s), or None when one is not diagonal or not positive (the steps handle it)."""
    d = np.diagonal(Q, axis1=1, axis2=2)
    off = Q.copy()
    off[:, np.arange(Q.shape[1]), np.arange(Q.shape[1])] = 0.0
    if not np.isfinite(Q).all() or off.any() or (d <= 0).any():
        return None
    return np.ascontiguousarray(np.sqrt(d))


def likelihood_factors(R, finite):
    """``(sel, fac, rdiag, rL, rinv, rconst)`` of one run (:func:`pf_run`): the components measured
    at each step of ``finite`` (steps, nz), and the factors of R (a stack (steps, nz, nz), or of
    one) restricted to them, those of ``noise_factor`` (what ``Model.loglik`` uses: the same
    numbers), one per distinct pair of measured components and R; None when one has no factor."""
    steps, nz = finite.shape
    sel = measured_steps(finite)
    keys = finite.astype(float)
    if len(R) > 1:
        both = finite[:, :, None] & finite[:, None, :]
        keys = np.concatenate([keys, np.where(both, R, 0.0).reshape(steps, -1)], axis=1)
    keys = np.ascontiguousarray(keys)  # each row one value of its bytes: a 1-d unique (fast)
    _, first, fac = np.unique(
        keys.view(np.dtype((np.void, keys.itemsize * keys.shape[1]))).ravel(), return_index=True, return_inverse=True
    )
    U = len(first)
    rdiag, rL, rinv, rconst = np.zeros(U, bool), np.zeros((U, nz, nz)), np.zeros((U, nz)), np.zeros(U)
    for u, k in enumerate(first):
        mask = finite[k]
        d = int(mask.sum())
        if not d:
            continue
        try:
            rdiag[u], L, inv, logdet = noise_factor(R[k % len(R)][np.ix_(mask, mask)])
        except np.linalg.LinAlgError:
            return None
        rconst[u] = logdet + d * LOG_2PI
        if rdiag[u]:
            rinv[u, :d] = inv
        else:
            rL[u, :d, :d] = L
    return sel, np.ascontiguousarray(fac.ravel(), dtype=np.int64), rdiag, rL, rinv, rconst


def applies(engine, model) -> bool:
    """Whether the loop computes what the steps compute for this model (the engine is the plain
    bootstrap one, :meth:`replay.filters.pf.PFEngine.run_all`): systematic resampling, the
    model's own kernels and Gaussian likelihood, its noise drawn by the filter (no ``sample_f``
    of its own)."""
    return (
        SCHEMES.get(engine.flt.resampling) is systematic  # the scheme the loop computes, not a replacement
        and model.kernels() is not None
        and derived_from_kernels(model)
        and type(model).sample_f is Model.sample_f
        and type(model).loglik is Model.loglik
    )
