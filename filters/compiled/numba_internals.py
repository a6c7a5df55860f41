"""Everything that reaches into numba's internals, in one file (numba is pinned to 0.68 in
pyproject.toml; a new numba is tried here first).

* Sealed cache files. numba keeps a bound copy's machine code beside it as pickles: an index
  (``.nbi``) and one data file per compiled signature (``.nbc``), unpickled when a function is
  first called. For the copies' functions those files are written sealed: a fixed-length
  header holding the SHA-256 of the rest (a pickled string: plain numba reading such an index
  sees another version and recompiles; it never unpickles the rest). A file is read once, its
  hash checked, and only then unpickled; a file without a valid seal (damaged, truncated, or
  written by something else) is never unpickled: it is removed and the function compiled again
  (:func:`guard` counts them for the whole copy before the first call, one line on the
  ``replay.kernels`` logger). The hashes detect damage (a bad disk, a truncated write, a stray
  edit); they do not stop an attacker who can write as the same user.
* :func:`cfunc`: a cfunc of a copy's function, cached sealed, which numba types by its declared
  first-class function type (5 µs to pass one to a run loop, not 15; a jit function: 50).
* :class:`Kernel`: a dispatcher called through its compiled entry point once typed (numba types
  every argument of every call: about 7 µs for each function argument).
* :func:`from_cache`: a run loop's declared signature loaded from numba's disk cache, or None.
* One writer at a time per function's cache (:func:`locked_save`, numba's ``save`` for every cache
  in the process): numba picks a data file's number from the index it read, unlocked, so two
  worker processes compiling two signatures of one function at once could leave the index
  naming one signature and the file holding the other's machine code (seen: a segfault).
"""

from __future__ import annotations

import hashlib
import io
import itertools
import os
import pickle
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from numba.core import config
from numba.core.caching import Cache, IndexDataCacheFile
from numba.core.dispatcher import Dispatcher

from . import files
from .files import log, note_once, write_private

SEAL = "replay-sha256:"
_HEAD = len(pickle.dumps(SEAL + "0" * 64, protocol=4))  # the header's length: fixed


def jit_disabled() -> bool:
    """Whether numba's JIT is disabled (``NUMBA_DISABLE_JIT=1``: every kernel is its Python function)."""
    return bool(config.DISABLE_JIT)


def _header(payload: bytes) -> bytes:
    return pickle.dumps(SEAL + hashlib.sha256(payload).hexdigest(), protocol=4)


def seal(payload: bytes) -> bytes:
    """``payload`` behind its SHA-256 header."""
    return _header(payload) + payload


def unseal(raw: bytes) -> bytes | None:
    """The payload of a sealed file, or None when its seal does not match (nothing unpickled)."""
    payload = raw[_HEAD:]
    return payload if len(raw) >= _HEAD and raw[:_HEAD] == _header(payload) else None


def _count(n: int, what: str) -> None:
    """Count ``n`` damaged files of ``what`` (removed); say it in one line."""
    files.CACHE_REPORT["damaged"] += n
    log.warning("kernel cache: %d damaged file%s of %s removed and compiled again", n, "s" * (n != 1), what)


class SealedCacheFile(IndexDataCacheFile):
    """numba's index and data files of one function, written sealed and read only when the seal
    matches (the class of a copy's functions' cache file, set by :func:`guard`)."""

    label = "a model"  # the copy's model, named in the note

    def _read_sealed(self, path) -> bytes | None:
        with open(path, "rb") as f:
            raw = f.read()
        payload = unseal(raw)
        if payload is None:  # damaged: never unpickled; removed, compiled again
            Path(path).unlink(missing_ok=True)
            _count(1, self.label)
        return payload

    def _load_index(self):
        try:
            payload = self._read_sealed(self._index_path)
        except OSError:  # absent (or unreadable): nothing cached
            return {}
        if payload is None:  # its data files are orphans now: removed, or a new index could name them
            for p in Path(self._cache_path).glob(self._index_name[: -len("nbi")] + "*.nbc"):
                p.unlink(missing_ok=True)
            return {}
        f = io.BytesIO(payload)
        if pickle.load(f) != self._version:
            return {}
        stamp, overloads = pickle.loads(f.read())
        return overloads if stamp == self._source_stamp else {}

    def _save_index(self, overloads):
        f = io.BytesIO()
        pickle.dump(self._version, f, protocol=-1)
        f.write(self._dump((self._source_stamp, overloads)))
        self._write(self._index_path, f.getvalue())

    def _load_data(self, name):
        payload = self._read_sealed(self._data_path(name))
        if payload is None:
            raise OSError("damaged")  # numba's load: no cache entry, compile
        return pickle.loads(payload)

    def _save_data(self, name, data):
        self._write(self._data_path(name), self._dump(data))

    def _write(self, path, payload: bytes) -> None:
        try:
            write_private(path, seal(payload))
        except OSError as e:  # e.g. a full disk: the compiled code runs, only not cached
            note_once(
                f"kernel cache {os.path.dirname(path)}: cannot write ({e.strerror or e}); compiled code not cached"
            )


def _seal_cache(cache, label: str) -> None:
    """Make numba's ``cache`` of one function (a dispatcher's or cfunc's) sealed."""
    if isinstance(cache, Cache) and type(cache._cache_file) is IndexDataCacheFile:
        cache._cache_file.__class__ = SealedCacheFile
        cache._cache_file.label = label


def guard(module, label: str) -> int:
    """Seal the numba caches of the copy ``module``'s functions, and before any is called remove
    its numba cache files whose seal does not match (counted, one line). Returns how many."""
    dirs = set()
    for fn in vars(module).values():
        if isinstance(fn, Dispatcher) and getattr(fn.py_func, "__module__", None) == module.__name__:
            _seal_cache(fn._cache, label)
            if isinstance(fn._cache, Cache):
                dirs.add(Path(fn._cache.cache_path))
    damaged = 0
    for d in dirs:
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
        _count(damaged, label)
    return damaged


def cfunc(fty, py, cached: bool, label: str = "a model"):
    """``numba.cfunc(fty.signature, cache=cached)(py)`` with its cache sealed before it is read,
    passed to a compiled function as the first-class function type ``fty`` without a check."""
    from numba.core import sigutils
    from numba.core.ccallback import CFunc

    res = CFunc(py, sigutils.normalize_signature(fty.signature), locals={}, options={})
    if cached:
        res.enable_caching()
        _seal_cache(res._cache, label)
    res.compile()
    res._numba_type_ = fty  # numba's typeof reads it
    res.__wrapper_address__ = lambda a=res.address: a  # the protocol numba asks first: no signature check
    return res


LOCK_WAIT = 30.0  # s: longest wait for another process's write of one function's cache


@contextmanager
def index_lock(index_path: str):
    """An exclusive ``flock`` on ``<index>.lock`` while the block runs, waited for at most :data:`LOCK_WAIT`
    (then, or where there is no ``flock``, the block runs unlocked, as numba's own save does)."""
    try:
        import fcntl

        fd = os.open(index_path + ".lock", os.O_CREAT | os.O_RDWR, 0o600)
    except (ImportError, OSError):
        fd = None
    try:
        end = time.monotonic() + LOCK_WAIT
        while fd is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > end:
                    break
                time.sleep(0.005)
        yield
    finally:
        if fd is not None:
            os.close(fd)  # releases the lock


def locked_save(self, key, data):
    """numba's ``IndexDataCacheFile.save`` as one critical section per function (:func:`index_lock`): read
    the index, take the key's data file (or the first free number), write the data, then the index that
    names it. numba's own writes the index first and holds no lock (module docstring); the files'
    format is numba's, so processes without this still read them."""
    with index_lock(self._index_path):
        overloads = self._load_index()
        name = overloads.get(key)
        if name is None:
            used = set(overloads.values())
            name = next(n for n in map(self._data_name, itertools.count(1)) if n not in used)
        self._save_data(name, data)
        if overloads.get(key) != name:
            overloads[key] = name
            self._save_index(overloads)


NUMBA_SAVE = IndexDataCacheFile.save  # numba's own (the race's control in the tests)
IndexDataCacheFile.save = locked_save


def from_cache(loop, sig) -> bool:
    """Whether numba's disk cache holds the dispatcher ``loop`` compiled for ``sig`` (then loaded)."""
    return loop._cache.load_overload(sig, loop.targetctx) is not None


def _key(args):
    """What numba's typing of ``args`` depends on: dtype, dimensions and layout (C, F or neither) of
    arrays, the type of anything else."""
    return tuple(
        (a.dtype.num, a.ndim, a.flags.c_contiguous, a.flags.f_contiguous) if isinstance(a, np.ndarray) else type(a)
        for a in args
    )


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
