"""Whole-run loops: what the compiled run loops of every filter family share.

A run loop (:func:`replay.util.kalman_loops.sigma_run`, ``ekf_run``,
:func:`replay.filters.pf_loop.pf_run`) runs every step of a run in one
compiled call. It calls the same step kernels as the step-by-step engine, and
the model's kernels are passed to it in their rows forms (:mod:`replay.filters.rows`
bound to the model, :func:`row_kernels`: one call per stack of states) as
first-class functions of one declared type: one compilation of the loop (cached
on disk by numba) serves every model.
A loop is used only for the model's own kernels (:func:`derived_from_kernels`)
and only when it is compiled already, or cached, or the job is big enough to
pay for its compilation (choosing by problem size: a short first run never
waits for it).
"""
from __future__ import annotations

import math

import numpy as np

COMPILE_AT = 200_000  # Kalman run-steps from which a missing run loop is compiled (~10 s, once per machine)
THREAD_WORK_US = 1000.0  # work per thread at least (waking a thread costs tens of µs)


def derived_from_kernels(model) -> bool:
    """True when the model's f, h, F, H are those a KernelModel derives from its kernels."""
    from replay.models.kernel_model import KernelModel

    return all(getattr(type(model), n) is getattr(KernelModel, n) for n in ("f", "h", "F", "H"))


_rows: dict = {}  # (kernels, index) -> cfunc
_copies: dict = {}  # kernels -> bound copy of replay.filters.rows


def row_kernels(model, needed=(0, 1, 2, 3)):
    """The rows forms ``f_rows, h_rows, F_rows, H_rows`` (:mod:`replay.filters.rows`) of the model's
    kernels, those of indices ``needed``, as cfuncs of the declared first-class types of the run
    loops: the template bound to the model (:mod:`replay.filters.binding`), compiled once per
    machine and cached on disk by numba beside the bound copy."""
    from replay.util import kalman_loops as kernels

    from . import binding, rows

    ks = model.kernels()
    ids = tuple(id(k) for k in ks)
    got = []
    for i in needed:
        key = (ids, i)
        fn = _rows.get(key)
        if fn is None:
            mod = _copies.get(key[0])
            if mod is None:
                mod = _copies[key[0]] = binding.bound_copy(rows, ks, (), "replay_rows_",
                                                           "the run loops' rows kernels (about 2 s)")
            fty = kernels.JACOBIAN_ROWS if i >= 2 else kernels.ROWS_KERNEL
            fn = _rows[key] = binding.cfunc(fty.signature, getattr(mod, ("f_rows", "h_rows", "F_rows", "H_rows")[i]))
            if hasattr(fn, "address"):  # compiled (with numba's JIT disabled: the Python function)
                fn._numba_type_ = fty  # numba's typeof reads it: 5 µs to pass a cfunc, not 15 (a jit function: 50)
                fn.__wrapper_address__ = lambda a=fn.address: a  # the protocol numba asks first: no signature check
        got.append(fn)
    return got


def grain(us_per_run: float) -> int:
    """Runs per thread at least, for runs of about ``us_per_run`` µs each (:data:`THREAD_WORK_US`)."""
    return max(1, math.ceil(THREAD_WORK_US / max(us_per_run, 1e-3)))


_bound: dict = {}


def bound(loop, *fns):
    """``loop`` with its first arguments ``fns`` (the model's kernels as first-class functions),
    called through its compiled entry point once typed (:class:`Kernel`)."""
    key = (loop, fns)
    got = _bound.get(key)
    if got is None:
        got = _bound[key] = Kernel(loop, *fns)
    return got


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


_stacks: dict = {}


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


def _key(args):
    """What numba's typing of ``args`` depends on: dtype, dimensions and layout (C, F or neither) of
    arrays, the type of anything else."""
    return tuple((a.dtype.num, a.ndim, a.flags.c_contiguous, a.flags.f_contiguous) if isinstance(a, np.ndarray)
                 else type(a) for a in args)


class Kernel:
    """``Kernel(dispatcher, fn1, fn2, ...)(*args)`` = ``dispatcher(fn1, fn2, ..., *args)``, typed once."""

    def __init__(self, dispatcher, *fns):
        self.dispatcher, self.fns = dispatcher, fns
        self.key, self.entry = None, None

    def __call__(self, *args):
        key = _key(args)
        if key == self.key:
            return self.entry(*self.fns, *args)
        out = self.dispatcher(*self.fns, *args)
        d = self.dispatcher
        if not hasattr(d, "overloads"):  # numba's JIT disabled: the Python function, nothing to type
            return out
        sig = tuple(d.typeof_pyval(a) for a in (*self.fns, *args))
        cres = d.overloads.get(sig)
        if cres is not None:
            self.key, self.entry = key, cres.entry_point
        return out
