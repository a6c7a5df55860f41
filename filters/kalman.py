"""Kalman filter and extended Kalman filter, over the Monte Carlo run axis.

Equations (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, 2001: §5.2 the Kalman filter, §5.4 the NIS, §10.3
the EKF), for each run:

    predict   x = f(x),  P = F P F' + Q                 F = df/dx at the prior
    update    y = z - h(x)  (angle components wrapped)
              S = H P H' + R,  K = P H' S^-1             H = dh/dx at the predicted state
              x = x + K y  (state angles wrapped)
              P = (I - K H) P (I - K H)' + K R K'        (Joseph form)
    NIS       y' S^-1 y, with nz (measured components) degrees of freedom

The Joseph form keeps P symmetric positive semi-definite. ``KalmanFilter`` is
the EKF applied to a linear model (its Jacobians are the model matrices), so
the two cannot drift apart.

The engine holds the means of the active runs ``x`` (M, nx) and their
covariances ``P`` (M, nx, nx); ``f``, ``h``, every product, Cholesky factor
and solve act on the whole stack, one matrix per run (see
:mod:`replay.util.linalg`), and ``model.F``/``model.H`` (a single state in the
model protocol) are called once per run. The functions are written over any
leading axes: a single run (M = 1) is held without the run axis, x (nx,) and
P (nx, nx), where numpy's per-call costs are lowest; each slice of a stack
gets the numbers of that case bit for bit (same LAPACK routines, same memory
layout per matrix). Runs whose measurements miss different components are
updated in groups of equal pattern (missing components are left out of z, h,
H and R).

:class:`KalmanEngine` is shared with the sigma-point filters of
:mod:`replay.filters.sigma`, which replace ``predict`` and ``update``.
"""

from __future__ import annotations

from functools import lru_cache
from time import perf_counter

import numpy as np

from replay.filters.case import Case
from replay.util.angles import angle_mask, residual, wrap_components
from replay.model import remap_indices

from . import gating
from . import kalman_kernels as kernels
from . import kalman_loops
from .base import Filter
from .compiled import bound, cov_stacks, derived_from_kernels, grain, loop_ready
from .compiled import measured_steps, param_stacks, row_kernels, split


def stack_of(a, one: bool):
    """``a`` as a C-ordered float stack with a leading run axis (a single run gets one)."""
    return np.ascontiguousarray(a[None] if one else a, dtype=float)


def not_pd(run: int) -> np.linalg.LinAlgError:
    return np.linalg.LinAlgError(f"innovation covariance not positive definite (run {run} of the stack)")


def gain_nis(S, Pxz, y):
    """K = Pxz S^-1 (..., nx, nz) and the NIS y' S^-1 y (...), for one run (S (nz, nz)) or a
    stack of runs (S (M, nz, nz)); compiled (:func:`replay.filters.kalman_kernels.gain_nis`, one Cholesky
    factor of S per run). LinAlgError when an S is not positive definite."""
    one = S.ndim == 2
    S3, P3, y2 = stack_of(S, one), stack_of(Pxz, one), stack_of(y, one)
    K, nis = np.empty(P3.shape), np.empty(len(S3))
    bad = kernels.gain_nis(S3, P3, y2, K, nis)
    if bad >= 0:
        raise not_pd(bad)
    return (K[0], nis[0]) if one else (K, nis)


def kalman_update(x, P, y, H, R, x_angles=(), gate=None):
    """The Kalman update (module docstring) over one run (x (nx,)) or a stack (M, nx): returns
    new x, P (Joseph form), NIS; compiled (:func:`replay.filters.kalman_kernels.joseph_update`),
    gated with ``gate``, a :data:`replay.filters.gating.Gate` (:class:`replay.filters.gating.Tally`; None:
    no gate). LinAlgError when an S is not positive definite."""
    one = x.ndim == 1
    x2, P3 = np.array(x[None] if one else x, dtype=float), np.array(P[None] if one else P, dtype=float)
    nis = np.empty(len(x2))
    args = (
        x2,
        P3,
        stack_of(y, one),
        stack_of(H, one),
        np.ascontiguousarray(R, dtype=float),
        angle_mask(tuple(x_angles), x2.shape[1]),
        nis,
    )
    bad = kernels.joseph_update(*args) if gate is None else kernels.joseph_update_gated(*args, gate)
    if bad >= 0:
        raise not_pd(bad)
    return (x2[0], P3[0], nis[0]) if one else (x2, P3, nis)


def propagate_cov(F, P, Q):
    """F P F' + Q for one run (P (nx, nx)) or a stack; compiled
    (:func:`replay.filters.kalman_kernels.propagate_cov`)."""
    one = P.ndim == 2
    out = np.empty((1,) + P.shape if one else P.shape)
    kernels.propagate_cov(stack_of(F, one), stack_of(P, one), np.ascontiguousarray(Q, dtype=float), out)
    return out[0] if one else out


def jacobians(fun, x, k, stacked=False):
    """``fun`` (model.F or model.H) at the state x (nx,) or each run's (M, nx): one call on the
    stack when the model's Jacobians take stacks (``stacked``, ``Model.vector_jacobians``), else
    one call per run. C order either way: products round by their operands' layout."""
    if x.ndim == 1 or stacked:
        return np.ascontiguousarray(fun(x, k), dtype=float)
    return np.stack([fun(xi, k) for xi in x])


def measurement(model, k, mask):
    """R_k and the measurement's angle indices, restricted to the measured components ``mask``."""
    R, angles = model.measurement_cov(k), model.z_angles
    if mask is not None:
        R, angles = R[np.ix_(mask, mask)], remap_indices(angles, mask)
    return R, angles


def groups(finite):
    """Runs sharing a measurement pattern: [(rows, mask or None for full)]."""
    patterns, inverse = np.unique(finite, axis=0, return_inverse=True)
    return [
        (np.flatnonzero(inverse.ravel() == g), None if pat.all() else pat)
        for g, pat in enumerate(patterns)
        if pat.any()
    ]


class KalmanEngine:
    """M runs of a Kalman-family filter: start, keep and the step; subclasses predict and update
    (over any leading axes: one run is held as x (nx,), P (nx, nx))."""

    GATES = True  # its updates gate (replay.filters.gating)

    def __init__(self, flt, model, rngs):
        self.flt, self.model = flt, model

    def start(self, X0, P0):
        self.one = len(X0) == 1
        self.x, self.P = (X0[0].copy(), P0[0].copy()) if self.one else (X0.copy(), P0.copy())
        self.nis1, self.dof1 = np.empty(1), np.empty(1, int)  # one run's NIS and its dof, per step
        self.tally, self.cut = gating.Tally(self.model, len(X0)), 0  # cut: components a gate rejected
        self.gated = self.tally.gates is not None

    def keep(self, ok):
        self.tally.keep(ok)
        if not self.one:
            self.x, self.P = self.x[ok], self.P[ok]

    def finish(self, m, info):
        self.tally.info(m, info)

    def gate(self, mask, rows, n):
        """The gate arguments of a gated update of ``n`` runs (``rows`` of the active ones) and, after
        it, the tally: (args, done) where done() adds the counts and returns the components cut."""
        args = self.tally.args(mask, n)

        def done():
            self.tally.add(args.rej, rows)
            return args.cut

        return args, done

    def step(self, k, Z, finite):
        x, P = self.predict(self.x, self.P, k)
        if self.one:
            f, nis = finite[0], np.nan
            dof = np.count_nonzero(f)
            if dof == len(f):
                x, P, nis = self.update(x, P, Z[0], k, None)
            elif dof:
                x, P, nis = self.update(x, P, Z[0][f], k, f)
            if dof and self.gated:
                dof -= int(self.cut[0])
            self.x, self.P = x, P
            self.nis1[0], self.dof1[0] = nis, dof
            return x[None], P[None], self.nis1, self.dof1
        if finite.all():
            self.x, self.P, nis = self.update(x, P, Z, k, None)
            return self.x, self.P, nis, np.full(len(x), Z.shape[1]) - self.cut
        nis, dof = np.full(len(x), np.nan), np.zeros(len(x), int)
        for rows, mask in groups(finite):
            z = Z[rows] if mask is None else Z[rows][:, mask]
            x[rows], P[rows], nis[rows] = self.update(x[rows], P[rows], z, k, mask, rows)
            dof[rows] = z.shape[1] - self.cut
        self.x, self.P = x, P
        return x, P, nis, dof

    def run_all(self, Z, finite):
        """Every step of the active runs at once, when each step has all measurements of every run or
        none (a missing row, the same for every run): the same
        kernels in one compiled loop (:func:`run_kernels`), returning (X, P, nis, dof) stacks (M,
        steps, ...), or False when a run failed (the caller redoes the steps one by one), or None
        when there is no such loop for this filter or model."""
        return None

    def predict(self, x, P, k):
        raise NotImplementedError

    def update(self, x, P, z, k, mask, rows=None):
        """The update of the runs ``rows`` (None: all active runs) of the predicted x, P."""
        raise NotImplementedError


def run_kernels(engine, Z, finite, kernels_needed, loop, sig, *args):
    """Run ``loop`` (:func:`replay.filters.kalman_loops.sigma_run` or ``ekf_run``, declared type
    ``sig``) over the engine's runs for the measurements Z (M, steps, nz): the model's one-state
    kernels (their rows forms, first-class functions: :func:`replay.filters.compiled.row_kernels`), its
    parameters, Q and R at every step (:func:`replay.filters.compiled.cov_stacks`), the components
    measured at each step (the same for every run; :func:`replay.filters.compiled.measured_steps`).
    None (the caller steps in Python, same numbers) when the runs measure different components at
    a step, or the model's array methods are not its kernels, or a subclass of the engine (a plugin's) changes a
    step, or when the loop is neither compiled nor cached and the job is smaller than
    ``COMPILE_AT`` run-steps (:func:`replay.filters.compiled.loop_ready`), or when the model gates its
    measurements (:mod:`replay.filters.gating`: the steps count the rejections)."""
    if not own_steps(engine) or gating.active(engine.model) is not None:  # gates: step by step
        return None
    m = engine.model
    ks = m.kernels()
    M, steps, nz = Z.shape
    if not (finite == finite[:1]).all():  # runs measuring different components at a step: steps
        return None
    if (
        ks is None
        or not derived_from_kernels(m)
        or not loop_ready(loop, sig, M * steps >= kalman_loops.COMPILE_AT, M * steps, kalman_loops.COMPILE_AT)
    ):
        return None
    stacks, covs = param_stacks(m, steps), cov_stacks(m, steps)
    if stacks is None or covs is None:  # parameters, Q or R of another shape at some step (ragged)
        return None
    Q, R = covs
    sel = measured_steps(finite[0])
    x, P = np.array(stack_of(engine.x, engine.one)), np.array(stack_of(engine.P, engine.one))
    X, PP, nis = np.empty((M, steps, m.nx)), np.empty((M, steps, m.nx, m.nx)), np.empty((M, steps))
    call = bound(loop, *row_kernels(m, kernels_needed))
    Z = np.ascontiguousarray(Z, dtype=float)
    xmask, zmask = np.array(angle_mask(m.x_angles, m.nx)), np.array(angle_mask(m.z_angles, nz))
    par = kalman_loops.Params(*stacks, Q)

    def runs(lo, hi):  # the runs are independent: the same numbers on any thread
        obs, out = kalman_loops.Obs(Z[lo:hi], sel, R, zmask), kalman_loops.Out(X[lo:hi], PP[lo:hi], nis[lo:hi])
        return call(x[lo:hi], P[lo:hi], obs, par, *args, xmask, out)

    t0 = perf_counter()
    bad = max(split(runs, M, grain=grain(4.0 * steps)))  # about 4 µs a run-step
    engine.seconds = perf_counter() - t0  # the computation, without loading the compiled code
    if bad >= 0:
        return False
    return X, PP, nis, sel[:, 0][None].repeat(M, axis=0)


def own_steps(engine) -> bool:
    """Whether the engine steps as the class whose ``run_all`` it has (its loop computes those steps)."""
    return _own_steps(type(engine))


@lru_cache(maxsize=None)
def _own_steps(cls) -> bool:
    owner = next(c for c in cls.__mro__ if "run_all" in vars(c))
    return all(getattr(cls, n) is getattr(owner, n) for n in ("start", "step", "keep", "predict", "update"))


class EKFEngine(KalmanEngine):
    """The EKF's predict and update on one run or a stack of runs."""

    def run_all(self, Z, finite):
        return run_kernels(self, Z, finite, (0, 1, 2, 3), kalman_loops.ekf_run, kalman_loops.EKF_RUN)

    def predict(self, x, P, k):
        m = self.model
        F = jacobians(m.F, x, k, m.vector_jacobians)
        x = wrap_components(m.f(x, k), m.x_angles)
        return x, propagate_cov(F, P, m.process_cov(k))

    def update(self, x, P, z, k, mask, rows=None):
        m = self.model
        H = jacobians(m.H, x, k, m.vector_jacobians)
        zh = m.h(x, k)
        R, angles = measurement(m, k, mask)
        if mask is not None:
            H, zh = H[..., mask, :], zh[..., mask]
        y = residual(z, zh, angles)
        if not self.gated:
            return kalman_update(x, P, y, H, R, m.x_angles)
        gate, done = self.gate(mask, rows, 1 if x.ndim == 1 else len(x))
        out = kalman_update(x, P, y, H, R, m.x_angles, gate)
        self.cut = done()
        return out


class EKF(Filter):
    """Extended Kalman filter (first order), with model or numerical Jacobians."""

    name = "ekf"
    PARAMS = ()

    def engine(self, model, rngs):
        return EKFEngine(self, model, rngs)


class KalmanFilter(EKF):
    """The Kalman filter: exact for :class:`replay.model.LinearGaussian` models."""

    name = "kf"
    CASE = Case("sim/ungm", "ungm", first=30)
    PARAMS = ()
