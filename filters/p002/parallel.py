"""Calling the compiled kernels of :mod:`replay.filters.p002.compiled`: argument typing once, threads.

:class:`Kernel` binds a kernel to the model's functions (``f``, ``h``, ...).
numba types every argument of every call, and a function argument costs
about 7 us each time; after the first call (which compiles, or loads from the
cache, and types) a :class:`Kernel` calls the compiled entry point directly,
as long as the arguments keep their types (checked on every call: dtype,
dimensions, layout; a change goes back through the dispatcher).

:func:`split` runs a kernel that takes a ``start, stop`` index range on
``threads()`` threads (the kernels release the GIL). Each index is computed by
one thread with the same arithmetic, so the numbers do not depend on the
thread count. The cubature step of :mod:`replay.filters.p002.stcpf` uses numba's
own (OpenMP) threads instead (``compiled.cubature_threads``): they spin between
steps, where waking a Python thread costs about 70 us, more than half a step
of one run takes. ``REPLAY_THREADS`` sets the count (default: the CPUs this
process may use, at most 8); campaign workers set it to 1.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

_pool = None
_pool_size = 0


def threads() -> int:
    n = os.environ.get("REPLAY_THREADS")
    if n:
        return max(1, int(n))
    return max(1, min(8, len(os.sched_getaffinity(0))))


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
        sig = tuple(d.typeof_pyval(a) for a in (*self.fns, *args))
        cres = d.overloads.get(sig)
        if cres is not None:
            self.key, self.entry = key, cres.entry_point
        return out


def _get_pool(n: int) -> ThreadPoolExecutor:
    global _pool, _pool_size
    if _pool is None or _pool_size < n:
        _pool, _pool_size = ThreadPoolExecutor(n, thread_name_prefix="replay-kernel"), n
    return _pool


def split(kernel, total: int, *args, grain: int = 1) -> None:
    """``kernel(*args, start, stop)`` over 0 .. total - 1, in one contiguous range per thread
    (``kernel`` may also be a Python function that calls kernels), at least ``grain`` indices
    per thread: waking a thread costs tens of microseconds, more than small ranges take."""
    n = min(threads(), total // max(grain, 1))
    if n <= 1:
        kernel(*args, 0, total)
        return
    pool = _get_pool(n)
    size = (total + n - 1) // n
    futures = [pool.submit(kernel, *args, j * size, min(total, (j + 1) * size)) for j in range(1, n)]
    kernel(*args, 0, min(total, size))  # the calling thread takes the first range
    for fut in futures:
        fut.result()
