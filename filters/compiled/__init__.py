"""The compiled-kernel machinery, fenced in: how a filter calls a compiled step. Its one way in.

The arithmetic lives elsewhere, each step once, as a ``numba.njit`` function whose Python text
is the reference (:mod:`replay.util.kernels`, :mod:`replay.filters.kalman_kernels`,
:mod:`replay.filters.particles`, paper 002's :mod:`replay.filters.p002.compiled`). This package
only calls it:

* :func:`bind` — a template module that calls a model's kernels ``f, h, F, H`` as globals,
  copied with that model's imports and cached on disk, content-keyed and sealed
  (:mod:`.copies`, :mod:`.files`);
* :func:`row_kernels`, :func:`loop_ready`, :func:`bound`, :func:`param_stacks`, :func:`cov_stacks`,
  :func:`measured_steps`, :func:`derived_from_kernels` — the whole-run loops' model kernels (rows forms, cfuncs of the
  declared types :data:`ROWS_KERNEL`, :data:`JACOBIAN_ROWS`), when a loop may run, and its call
  with the argument typing done once (:mod:`.loops`);
* :class:`Kernel` — a kernel called through its compiled entry point once typed;
* :func:`split`, :func:`threads`, :func:`grain` — index ranges on threads (:mod:`.threadpool`).

Only :mod:`.numba_internals` reaches into numba's internals (and :mod:`replay.util.kernel_cache`,
for numba's cache files of every replay function, the model kernels' included). Fallbacks (docs/architecture.md,
"How a compiled step is called"): with ``NUMBA_DISABLE_JIT=1`` every kernel, copy, cfunc and
loop is its Python function (the same numbers); a cache directory that cannot be used compiles
in memory (one note), a damaged cache file is removed and compiled again; a model without
kernels, or a filter engine that is not the library's own, steps in Python.
"""

from .copies import bind
from .loops import JACOBIAN_ROWS, ROWS_KERNEL, bound, cov_stacks, derived_from_kernels, grain, loop_ready
from .loops import measured_steps, param_stacks, row_kernels
from .numba_internals import Kernel
from .threadpool import split, threads

__all__ = [
    "JACOBIAN_ROWS",
    "Kernel",
    "ROWS_KERNEL",
    "bind",
    "bound",
    "cov_stacks",
    "derived_from_kernels",
    "grain",
    "loop_ready",
    "measured_steps",
    "param_stacks",
    "row_kernels",
    "split",
    "threads",
]
