"""Whole-run loops: what the compiled run loops of every filter family share.

A run loop (:func:`replay.filters.kalman_loops.sigma_run`, ``ekf_run``,
:func:`replay.filters.pf_loop.pf_run`) runs every step of a run in one compiled call. It calls
the same step kernels as the step-by-step engine, and the model's kernels are passed to it in
their rows forms (:mod:`.rows` bound to the model, :func:`row_kernels`: one call per stack of
states) as first-class functions of one declared type (:data:`ROWS_KERNEL`,
:data:`JACOBIAN_ROWS`): one compilation of the loop (cached on disk by numba) serves every
model. A loop is used only for the model's own kernels (:func:`derived_from_kernels`) and only
when it is compiled already, or cached, or the job is big enough to pay for its compilation
(:func:`loop_ready`: a short first run never waits for it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import types

from . import copies, numba_internals, rows
from .files import log
from replay.models.kernel_model import KernelModel
from replay.model import Model

THREAD_WORK_US = 1000.0  # work per thread at least (waking a thread costs tens of µs)
_VEC, _S2, _S3 = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1]
ROWS_KERNEL = types.FunctionType(types.void(_S2, _VEC, _S2))  # f, h: (X, p, out)
JACOBIAN_ROWS = types.FunctionType(types.void(_S2, _VEC, _S3))  # F, H: (X, p, J)


def derived_from_kernels(model) -> bool:
    """True when the model's f, h, F, H are those a KernelModel derives from its kernels."""
    return all(getattr(type(model), n) is getattr(KernelModel, n) for n in ("f", "h", "F", "H"))


_rows: dict = {}  # (kernels, index) -> cfunc


def row_kernels(model, needed=(0, 1, 2, 3)):
    """The rows forms ``f_rows, h_rows, F_rows, H_rows`` (:mod:`.rows`) of the model's kernels, those
    of indices ``needed``, as cfuncs of the declared first-class types of the run loops: the
    template bound to the model (:func:`.copies.bind`), compiled once per machine and cached on
    disk beside the bound copy (with numba's JIT disabled: the Python functions)."""
    ks = model.kernels()
    ids = tuple(id(k) for k in ks)
    got = []
    for i in needed:
        fn = _rows.get((ids, i))
        if fn is None:
            mod = copies.bind(rows, ks, "the run loops' rows kernels (about 2 s)")
            fn = _rows[ids, i] = copies.cfunc(
                JACOBIAN_ROWS if i >= 2 else ROWS_KERNEL, getattr(mod, ("f_rows", "h_rows", "F_rows", "H_rows")[i])
            )
        got.append(fn)
    return got


_ready: set = set()
_waiting: dict = {}  # loop -> work this process did without it (not compiled, not cached)


def loop_ready(loop, sig, compile_ok: bool, work: float = 0.0, at: float = math.inf) -> bool:
    """Whether the run loop ``loop`` can be called with its declared signature ``sig``: compiled in
    this process, or loaded from numba's disk cache, or (``compile_ok``) compiled now (about 10 s,
    once per machine). Compiled lazily, not at import: a short run never waits for it; but many
    short runs in one process (a tune's trials) compile it once their ``work`` (run-steps or
    particle-steps) adds up to ``at``. With numba's JIT disabled the loop is its Python function:
    always ready."""
    if (loop, id(sig)) in _ready:  # numba's ``loop.signatures`` costs 35 µs a call, hashing ``sig`` 30
        return True
    if numba_internals.jit_disabled():
        return True
    if not loop.signatures:
        if not numba_internals.from_cache(loop, sig):
            _waiting[loop] = _waiting.get(loop, 0.0) + work
            if not (compile_ok or _waiting[loop] >= at):
                return False
            log.info("compiling the run loop %s (about 12 s, once per machine; cached for later runs)", loop.__name__)
        loop.compile(sig)
        loop.disable_compile()  # one type for every model: the kernels convert to it
    _ready.add((loop, id(sig)))  # the declared signatures are module constants
    return True


def grain(us_per_run: float) -> int:
    """Runs per thread at least, for runs of about ``us_per_run`` µs each (:data:`THREAD_WORK_US`)."""
    return max(1, math.ceil(THREAD_WORK_US / max(us_per_run, 1e-3)))


_bound: dict = {}


def bound(loop, *fns):
    """``loop`` with its first arguments ``fns`` (the model's kernels as first-class functions),
    called through its compiled entry point once typed (:class:`.numba_internals.Kernel`)."""
    got = _bound.get((loop, fns))
    if got is None:
        got = _bound[loop, fns] = numba_internals.Kernel(loop, *fns)
    return got


_stacks: dict = {}


def param_stacks(model, steps: int):
    """The kernels' parameters of every step, ``(Pf, Ph)`` stacks (steps, p), or None when they
    change shape from step to step (ragged: the caller steps in Python, same numbers).

    Shared (the loops only read them) and kept for the last few models, keyed by the model's
    class, ``steps`` and the bytes of every attribute (:func:`fingerprint`): a model changed in
    any way, in place included, misses."""
    key = fingerprint(model, steps)
    if key is not None and key in _stacks:
        return _stacks[key]
    try:
        pars = [model.kernel_params(k) for k in range(steps)]
        got = tuple(np.ascontiguousarray([p[i] for p in pars], dtype=float) for i in (0, 1))
    except ValueError:
        got = None
    if key is not None:
        while len(_stacks) >= 8:
            _stacks.pop(next(iter(_stacks)))
        _stacks[key] = got
    return got


def fingerprint(model, steps: int):
    """A key that changes whenever anything the model's parameters may depend on changes: its class,
    ``steps`` and each attribute (arrays by dtype, shape and bytes); None (no cache) when an
    attribute is neither an array nor a number, string or None."""
    parts = [type(model), steps]
    for name, v in sorted(vars(model).items()):
        if isinstance(v, np.ndarray):
            parts.append((name, v.dtype.str, v.shape, v.tobytes()))
        elif v is None or isinstance(v, (bool, int, float, str)):
            parts.append((name, type(v), v))
        else:
            return None
    return tuple(parts)


def measured_steps(finite) -> np.ndarray:
    """The components measured at each step, for the run loops: ``finite`` (steps, nz) -> ``sel``
    (steps, nz + 1) int64, row k = [d, i_0 .. i_{d-1}, ...]: the d measured components of step k
    in increasing order (the rest of the row is not read). d = nz: all; d = 0: no update."""
    finite = np.asarray(finite, bool)
    sel = np.empty((len(finite), finite.shape[1] + 1), np.int64)
    sel[:, 0] = finite.sum(axis=1)
    sel[:, 1:] = np.argsort(~finite, axis=1, kind="stable")
    return sel


def cov_stacks(model, steps: int):
    """``(Q, R)``: the model's process and measurement noise covariances of every step, stacks
    (steps, n, n), or a stack of one (1, n, n) when the model's are constant (``model.Q``,
    ``model.R``); None when they change shape from step to step (the caller steps in Python).

    A time-varying model may give a whole stack at once, ``process_covs(steps)`` and
    ``measurement_covs(steps)`` (the first ``steps`` matrices, equal to its ``process_cov(k)``,
    ``measurement_cov(k)``): used unless the instance replaces the one-step method without the
    stack (a wrapper that changes the numbers, e.g. a scale, must wrap both); else one call per step."""
    out = []
    for one, many, const in (("process_cov", "process_covs", "Q"), ("measurement_cov", "measurement_covs", "R")):
        if getattr(type(model), one) is getattr(Model, one) and one not in vars(model):
            got = np.asarray(getattr(model, const), dtype=float)[None]
        elif hasattr(model, many) and (one not in vars(model) or many in vars(model)):
            got = getattr(model, many)(steps)
        else:
            try:
                got = [getattr(model, one)(k) for k in range(steps)]
            except ValueError:
                return None
        try:
            out.append(np.ascontiguousarray(got, dtype=float))
        except ValueError:  # ragged
            return None
    return tuple(out)
