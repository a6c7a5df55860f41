"""Calling the compiled kernels of :mod:`replay.filters.p002.compiled`: argument typing once, threads.

:class:`Kernel` (:mod:`replay.filters.loops`) binds a kernel to the model's functions (``f``, ``h``, ...).
numba types every argument of every call, and a function argument costs
about 7 us each time; after the first call (which compiles, or loads from the
cache, and types) a :class:`Kernel` calls the compiled entry point directly,
as long as the arguments keep their types (checked on every call: dtype,
dimensions, layout; a change goes back through the dispatcher).

:func:`split` (:mod:`replay.filters.threads`) runs a kernel that takes a ``start, stop``
index range on ``threads()`` threads (the kernels release the GIL). Each index is computed by
one thread with the same arithmetic, so the numbers do not depend on the
thread count. The cubature step of :mod:`replay.filters.p002.stcpf` uses numba's
own (OpenMP) threads instead (``compiled.cubature_threads``): they spin between
steps, where waking a Python thread costs about 70 us, more than half a step
of one run takes. ``REPLAY_THREADS`` sets the count (default: the CPUs this
process may use, at most 8); campaign workers set it to 1.
"""
from __future__ import annotations

from replay.filters.loops import Kernel  # noqa: F401  (this module's API since paper 002)
from replay.filters.threads import split, threads  # noqa: F401
