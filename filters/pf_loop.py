"""The bootstrap PF's whole run in one compiled loop: the steps of :class:`replay.filters.pf.PFEngine`.

For one run, every step k (module docstring of :mod:`replay.filters.pf`)::

    propagate   x^i <- f(x^i) + sd * e^i,   e^i ~ N(0, I) from the run's generator   (particles.perturb)
    weight      l^i <- l^i + log N(z_k; h(x^i), R)          (replay.util.kernels.gauss_loglik)
    normalise   w, l <- particles.weights(l)                   (log domain)
    estimate    x_k, P_k <- particles.moments(x, w)          (circular means for angles)
    resample    when ESS = 1 / sum w^2 < threshold * N (particles.ess_rows): systematic
                (resampling.invert_sorted), then roughening (particles.roughen) when K > 0

The same kernels as the step-by-step engine, and the same draws from the same
``numpy.random.Generator`` in the same order (numba draws from a NumPy
generator with NumPy's own algorithms, sharing its state): the loop gives the
numbers of the steps bit for bit, and leaves the generator where the steps
leave it (``tests/test_pf_loop.py``). The steps remain the readable reference
and the general path: partly missing measurements, models that draw their own noise,
a non-diagonal Q, time-varying Q or R, gated measurements (:mod:`replay.filters.gating`),
other resampling schemes and subclasses that change the weighting all step in Python.
"""

from __future__ import annotations

from time import perf_counter

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
import numpy as np
from numba import types

from replay.model import Model, noise_factor
from replay.util.angles import angle_mask
from replay.util.kernels import LOG_2PI, gauss_loglik

from .compiled import ROWS_KERNEL, bound, derived_from_kernels, grain, loop_ready, param_stacks, row_kernels, split
from .particles import ess_rows, moments, perturb, roughen, weights
from .resampling import SCHEMES, invert_sorted, systematic

# particle-steps from which the missing loop is compiled (~2 s, once per machine; it saves
# 0.2-0.3 µs per particle-step against the steps: their Python and numpy calls per run and step)
COMPILE_AT = 10_000_000


@nb.njit(cache=True, nogil=True)
def pf_run(
    f,
    h,
    g,
    X,
    logw,
    w,
    Z,
    seen,
    Pf,
    Ph,
    qsd,
    rdiag,
    rL,
    rinv,
    rconst,
    xmask,
    zmask,
    limit,
    rough,
    logw0,
    Xout,
    Pout,
    ess,
):
    """Every step of one run of the bootstrap PF (module docstring). X (N, n) particles, logw and
    w (N,) their log-weights and weights (all changed in place); Z (steps, nz), ``seen[k]``
    whether z_k is there (else no weighting at k); Pf[k], Ph[k] the
    kernels' parameters; qsd (n,) the process noise's standard deviations; R as ``gauss_loglik``
    takes it (rdiag, rL, rinv, rconst); ``limit`` = threshold * N; roughening constant
    ``rough`` = K; ``logw0`` = -log N. Writes Xout (steps, n), Pout (steps, n, n) and ess (steps,),
    the ESS before resampling. Returns the number of resampling steps."""
    N, n = X.shape
    steps, nz = Z.shape
    Y, zh, ll = np.empty((N, n)), np.empty((N, nz)), np.empty(N)
    a, e1 = np.empty(N, np.int64), np.empty(1)
    count = 0
    for k in range(steps):
        f(X, Pf[k], Y)  # propagate: f on every particle, then the noise
        perturb(Y, qsd, g)
        X, Y = Y, X
        if seen[k]:  # weight (no measurement: the weights stay)
            h(X, Ph[k], zh)
            gauss_loglik(zh, Z[k], zmask, rdiag, rL, rinv, rconst, ll)
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
PF_RUN = types.int64(
    ROWS_KERNEL,
    ROWS_KERNEL,
    _GEN,
    _M,
    _V,
    _V,
    _M,
    types.boolean[::1],
    _M,
    _M,
    _V,
    types.boolean,
    _M,
    _V,
    types.float64,
    types.boolean[::1],
    types.boolean[::1],
    types.float64,
    types.float64,
    types.float64,
    _M,
    _M3,
    _V,
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
    seen = finite.all(axis=2)
    if (seen != finite.any(axis=2)).any():  # some measurement partly missing: the steps mask components
        return None
    if (
        not applies(engine, m)
        or not all(isinstance(g, np.random.Generator) for g in engine.active)
        or not loop_ready(pf_run, PF_RUN, M * steps * N >= COMPILE_AT)
    ):
        return None
    try:  # a covariance without a factor: the steps meet it and record the divergence
        (qdiag, qsd, _, _), (rdiag, rL, rinv, logdet) = noise_factor(m.Q), noise_factor(m.R)
    except np.linalg.LinAlgError:
        return None
    stacks = param_stacks(m, steps)
    if not qdiag or stacks is None:
        return None
    rL = np.ascontiguousarray(np.zeros((0, 0)) if rdiag else rL)
    rinv = np.ascontiguousarray(rinv if rdiag else np.zeros(0))
    call = bound(pf_run, *row_kernels(m, (0, 1)))
    xmask, zmask = np.array(angle_mask(m.x_angles, m.nx)), np.array(angle_mask(m.z_angles, nz))
    X, P, E = np.empty((M, steps, m.nx)), np.empty((M, steps, m.nx, m.nx)), np.empty((M, steps))
    Z = np.ascontiguousarray(Z, dtype=float)
    qsd = np.ascontiguousarray(qsd)
    fixed = (
        rdiag,
        rL,
        rinv,
        logdet + nz * LOG_2PI,
        xmask,
        zmask,
        flt.ess_threshold * N,
        float(flt.roughening),
        float(engine.logw0),
    )

    def runs(lo, hi):  # each run from its own generator: the same numbers on any thread (~0.15 µs
        # a particle-step)
        return [
            call(
                engine.active[j],
                *(np.ascontiguousarray(a[j]) for a in (engine.X, engine.logw, engine.w)),
                Z[j],
                seen[j],
                *stacks,
                qsd,
                *fixed,
                X[j],
                P[j],
                E[j],
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


def applies(engine, model) -> bool:
    """Whether the loop computes what the steps compute for this model (the engine is the plain
    bootstrap one, :meth:`replay.filters.pf.PFEngine.run_all`): systematic resampling, the
    model's own kernels, its noise drawn by the filter (no ``sample_f`` of its own), Q and R
    constant."""
    return (
        SCHEMES.get(engine.flt.resampling) is systematic  # the scheme the loop computes, not a replacement
        and model.kernels() is not None
        and derived_from_kernels(model)
        and type(model).sample_f is Model.sample_f
        and type(model).process_cov is Model.process_cov
        and type(model).measurement_cov is Model.measurement_cov
    )
