"""Rauch–Tung–Striebel smoothers: ``ekf+rts``, ``ukf+rts``, ``ckf+rts`` (and ``kf+rts``).

A smoother row is its forward filter (:class:`replay.filters.kalman.EKF`,
:class:`~replay.filters.sigma.UKF`, :class:`~replay.filters.sigma.CKF`, with the same
parameters) run by the one run loop (:meth:`replay.filters.base.Filter.run_batch`), followed by
the backward pass of :mod:`replay.filters.rts_loops` over all of its runs at once: the
estimates of step k are then those given every measurement of the run, before and after k
(Särkkä 2013, Theorem 8.2 and §9.1, §9.3, §9.5: the extended, unscented and cubature RTS
smoothers). Replay is offline: the smoother bounds what a causal filter of the same model can
reach on a recording.

* The backward pass is compiled where the forward pass is (the model's kernels in their rows
  forms, :func:`replay.filters.compiled.row_kernels`, a loop compiled once per machine and
  cached, run when :func:`replay.filters.compiled.loop_ready` says so); otherwise the same
  loop's Python text runs with the model's own ``f`` and ``F`` (and, with
  ``NUMBA_DISABLE_JIT=1``, every kernel is Python: the same numbers).
* A run whose forward pass diverged at step d is smoothed over its steps before d (the
  estimates from d on stay NaN, ``diverged_at`` stays d). A run whose predicted covariance has
  no Cholesky factor in the backward pass is diverged at 0 with ``info["error"]`` naming the
  step: a filtered estimate is never passed off as a smoothed one.
* ``info["nis"]`` is the forward filter's (the innovations are the filter's); the time per step
  is the forward pass's plus the backward pass's.
"""

from __future__ import annotations

from time import perf_counter

import numpy as np

from replay.util.angles import angle_mask

from . import kalman_loops, noise_params, rts_loops
from .base import Estimates, Filter
from .case import Case
from .compiled import bound, cov_stacks, derived_from_kernels, grain, loop_ready, param_stacks, row_kernels, split
from .kalman import EKF, KalmanFilter, jacobians
from .kalman_kernels import Rule
from .sigma import CKF, UKF


class RTSSmoother(Filter):
    """The forward filter ``FORWARD`` and the RTS backward pass over its estimates (module docstring)."""

    FORWARD: type = EKF
    PARAMS = ()
    OFFLINE = True  # uses every measurement of a run: the leaderboards' gap to the optimum (replay.scoring.gap)

    def forward(self) -> Filter:
        """The forward filter with this row's parameters (the noise settings are the pipeline's:
        applied to the model before :meth:`run_batch`)."""
        own = {p.name: getattr(self, p.name) for p in self.FORWARD.PARAMS if p.name not in noise_params.NAMES}
        return self.FORWARD(**own)

    def engine(self, model, rngs):
        """The forward filter's engine (the filtered estimates; :meth:`run_batch` smooths them)."""
        return self.forward().engine(model, rngs)

    def run_batch(self, model, Z, X0, P0, rngs) -> list[Estimates]:
        return smooth(self, model, self.forward().run_batch(model, Z, X0, P0, rngs))

    def backward(self, model):
        """(loop, signature, the model kernels it takes (indices of f, h, F, H), its own arguments)."""
        return rts_loops.ekf_smooth_run, rts_loops.EKF_SMOOTH, (0, 2), ()


class EKFRTS(RTSSmoother):
    """The EKF and the extended RTS smoother (Särkkä 2013, §9.1; eq. 8.6 on a linear model)."""

    name = "ekf+rts"
    FORWARD = EKF


class KFRTS(EKFRTS):
    """The Kalman filter and the RTS smoother (Särkkä 2013, Theorem 8.2, eq. 8.6): exact on
    :class:`replay.model.LinearGaussian` models."""

    name = "kf+rts"
    FORWARD = KalmanFilter
    CASE = Case("sim/ungm", "ungm", first=30)


class SigmaRTS(RTSSmoother):
    """A sigma-point filter and its RTS smoother on the same points and weights."""

    def backward(self, model):
        xi, wm, wc = self.forward().points(model.nx)
        extra = (Rule(np.ascontiguousarray(xi), wm, wc), bool(model.mean_at_f))
        return rts_loops.sigma_smooth_run, rts_loops.SIGMA_SMOOTH, (0,), extra


class UKFRTS(SigmaRTS):
    """The UKF and the unscented RTS smoother (Särkkä 2008; Särkkä 2013, §9.3)."""

    name = "ukf+rts"
    FORWARD = UKF
    CASE = Case(params={"alpha": 0.8})
    PARAMS = UKF.PARAMS


class CKFRTS(SigmaRTS):
    """The CKF and the cubature RTS smoother (Särkkä 2013, §9.5: the Gaussian RTS
    smoother with the third-degree spherical-radial rule)."""

    name = "ckf+rts"
    FORWARD = CKF


def smooth(flt: RTSSmoother, model, out: list[Estimates]) -> list[Estimates]:
    """The smoothed estimates of the forward pass's ``out`` (one per run, same order): the runs
    that did not diverge in one batch, each diverged run alone over its steps before divergence."""
    n = len(out[0].x) if out else 0
    whole = [m for m, e in enumerate(out) if not e.diverged]
    batches = ([(whole, n)] if whole else []) + [([m], e.diverged_at) for m, e in enumerate(out) if e.diverged]
    res = list(out)
    for rows, length in batches:
        if length < 1:
            continue
        X = np.ascontiguousarray([out[m].x[:length] for m in rows], dtype=float)
        P = np.ascontiguousarray([out[m].P[:length] for m in rows], dtype=float)
        Xs, Ps, bad, secs = backward_pass(flt, model, X, P)
        per_step = secs / (length * len(rows))
        if bad >= 0 and len(rows) > 1:  # which run failed: each alone (a run's numbers do not depend on its batch)
            for m in rows:
                res[m] = _smoothed(out[m], *_one(flt, model, out[m], length), length, per_step)
            continue
        for j, m in enumerate(rows):
            res[m] = _smoothed(out[m], Xs[j], Ps[j], bad, length, per_step)
    return res


def _one(flt, model, est, length):
    Xs, Ps, bad, _ = backward_pass(flt, model, est.x[None, :length].copy(), est.P[None, :length].copy())
    return Xs[0], Ps[0], bad


def _smoothed(est: Estimates, xs, Ps, bad: int, length: int, per_step: float) -> Estimates:
    """The Estimates of one smoothed run (module docstring: a failed backward pass is diverged at 0)."""
    info = dict(est.info)
    x, P = np.full_like(est.x, np.nan), np.full_like(est.P, np.nan)
    if bad >= 0:
        info["error"] = f"LinAlgError: RTS smoother: predicted covariance of step {bad + 1} not positive definite"
        return Estimates(x, P, est.step_seconds + per_step, 0, info)
    x[:length], P[:length] = xs, Ps
    return Estimates(x, P, est.step_seconds + per_step, est.diverged_at, info)


def backward_pass(flt: RTSSmoother, model, X, P):
    """(Xs, Ps, bad, seconds): the backward pass over the filtered X (M, steps, nx), P (M, steps, nx,
    nx); bad -1, or the step whose prediction had no Cholesky factor; the seconds of its computation
    (not the one-time loading of compiled code, as the forward loops' ``engine.seconds``). Compiled when the model's
    kernels are its methods and the loop is ready (:func:`replay.filters.compiled.loop_ready`,
    the forward loops' threshold); else the loop's Python text with the model's methods."""
    M, steps, nx = X.shape
    loop, sig, needed, extra = flt.backward(model)
    covs = cov_stacks(model, steps)
    Q = covs[0] if covs is not None else np.ascontiguousarray([model.process_cov(k) for k in range(steps)], float)
    xmask = np.array(angle_mask(model.x_angles, nx))
    Xs, Ps = np.empty(X.shape), np.empty(P.shape)
    at = kalman_loops.COMPILE_AT
    stacks = param_stacks(model, steps) if model.kernels() is not None and derived_from_kernels(model) else None
    if stacks is not None and loop_ready(loop, sig, M * steps >= at, M * steps, at):
        call = bound(loop, *row_kernels(model, needed))

        def runs(lo, hi):  # the runs are independent: the same numbers on any thread
            return call(X[lo:hi], P[lo:hi], stacks[0], Q, *extra, xmask, Xs[lo:hi], Ps[lo:hi])

        t0 = perf_counter()
        bad = max(split(runs, M, grain=grain(4.0 * steps)))
        return Xs, Ps, bad, perf_counter() - t0
    steps_k = np.arange(steps, dtype=float)[:, None]  # the Python path's "parameters": the step
    fns = [_python_rows(model, i) for i in needed]
    t0 = perf_counter()
    bad = getattr(loop, "py_func", loop)(*fns, X, P, steps_k, Q, *extra, xmask, Xs, Ps)
    return Xs, Ps, bad, perf_counter() - t0


def _python_rows(model, i: int):
    """The model's f (i = 0) or F (i = 2) as a rows kernel ``(X, p, out)`` of the Python path,
    ``p[0]`` the step."""
    if i == 0:

        def f_rows(X, p, out):
            out[:] = model.f(X, int(p[0]))

        return f_rows

    def F_rows(X, p, J):
        J[:] = jacobians(model.F, X, int(p[0]), model.vector_jacobians)

    return F_rows
