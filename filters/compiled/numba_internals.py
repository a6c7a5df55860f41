"""Everything that reaches into numba's internals, in one file (numba is pinned to 0.68 in
pyproject.toml; a new numba is tried here first).

* Sealed cache files (:mod:`replay.util.kernel_cache`, which locks, seals and checks numba's cache
  files of every function of replay): :func:`guard` removes a copy's files whose seal does not
  match before its first call.
* :func:`cfunc`: a cfunc of a copy's function, cached sealed, which numba types by its declared
  first-class function type (5 µs to pass one to a run loop, not 15; a jit function: 50).
* :class:`Kernel`: a dispatcher called through its compiled entry point once typed (numba types
  every argument of every call: about 7 µs for each function argument).
* :func:`from_cache`: a run loop's declared signature loaded from numba's disk cache, or None.
* One writer at a time per function's cache, and no reader in between: :mod:`replay.util.kernel_cache`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numba.core import config, sigutils
from numba.core.caching import Cache
from numba.core.ccallback import CFunc
from numba.core.dispatcher import Dispatcher

from replay.util.kernel_cache import adopt, cache_key, count, unseal


def jit_disabled() -> bool:
    """Whether numba's JIT is disabled (``NUMBA_DISABLE_JIT=1``: every kernel is its Python function)."""
    return bool(config.DISABLE_JIT)


def guard(module, label: str) -> int:
    """Seal the numba caches of the copy ``module``'s functions, and before any is called remove
    its numba cache files whose seal does not match (counted, one line). Returns how many."""
    dirs = set()
    for fn in vars(module).values():
        if isinstance(fn, Dispatcher) and getattr(fn.py_func, "__module__", None) == module.__name__:
            adopt(fn._cache, label)
            if isinstance(fn._cache, Cache):
                dirs.add(Path(fn._cache.cache_path))
    damaged = 0
    for d in dirs if cache_key() is not None else ():  # without a key nothing is read: nothing to check
        for p in sorted(d.glob(module.__name__ + ".*.nb[ic]"), key=lambda p: p.suffix != ".nbi"):  # indexes first
            try:
                if unseal(p.read_bytes()) is None:
                    p.unlink()
                    damaged += 1
                    if p.suffix == ".nbi":  # its data files are orphans: removed unread
                        for q in d.glob(p.name[: -len("nbi")] + "*.nbc"):
                            q.unlink(missing_ok=True)
                elif p.stat().st_mode & 0o077:
                    p.chmod(0o600)
            except OSError:
                continue  # removed meanwhile by another process, or unreadable: numba's load skips it
    if damaged:
        count(damaged, label)
    return damaged


def cfunc(fty, py, cached: bool, label: str = "a model"):
    """``numba.cfunc(fty.signature, cache=cached)(py)`` with its cache sealed before it is read,
    passed to a compiled function as the first-class function type ``fty`` without a check."""
    res = CFunc(py, sigutils.normalize_signature(fty.signature), locals={}, options={})
    if cached:
        res.enable_caching()
        adopt(res._cache, label)
    res.compile()
    res._numba_type_ = fty  # numba's typeof reads it
    res.__wrapper_address__ = lambda a=res.address: a  # the protocol numba asks first: no signature check
    return res


def from_cache(loop, sig) -> bool:
    """Whether numba's disk cache holds the dispatcher ``loop`` compiled for ``sig`` (then loaded)."""
    return loop._cache.load_overload(sig, loop.targetctx) is not None


def _key(args):
    """What numba's typing of ``args`` depends on: dtype, dimensions and layout (C, F or neither) of
    arrays, the type and the fields' keys of a tuple (the packed arguments), the type of anything else."""
    out = []  # a loop, not a generator: this runs on every call (~5 µs for a run loop's arguments)
    for a in args:
        if isinstance(a, np.ndarray):
            f = a.flags
            out.append((a.dtype.num, a.ndim, f.c_contiguous, f.f_contiguous))
        elif isinstance(a, tuple):
            out.append((type(a), _key(a)))
        else:
            out.append(type(a))
    return tuple(out)


class Kernel:
    """``Kernel(dispatcher, fn1, fn2, ...)(*args)`` = ``dispatcher(fn1, fn2, ..., *args)``: after the
    first call (which compiles, or loads from the cache, and types) the compiled entry point is
    called directly as long as the arguments keep their types (dtype, dimensions, layout; checked
    on every call, a change goes back through the dispatcher). With numba's JIT disabled: the
    Python function."""

    def __init__(self, dispatcher, *fns):
        self.dispatcher, self.fns = dispatcher, fns
        self.key, self.entry = None, None

    def __call__(self, *args):
        key = _key(args)
        if key == self.key:
            return self.entry(*self.fns, *args)
        out = self.dispatcher(*self.fns, *args)
        d = self.dispatcher
        if isinstance(d, Dispatcher):
            cres = d.overloads.get(tuple(d.typeof_pyval(a) for a in (*self.fns, *args)))
            if cres is not None:
                self.key, self.entry = key, cres.entry_point
        return out
