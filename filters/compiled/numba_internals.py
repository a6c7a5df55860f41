"""The files of the kernel cache (:mod:`replay.filters.binding`): an owner-only directory, and
numba's cache files of the bound copies sealed with their SHA-256.

numba keeps a copy's machine code beside it as pickles: an index (``.nbi``)
and one data file per compiled signature (``.nbc``), unpickled when a
function is first called. For the copies' functions those files are written
sealed: a fixed-length header holding the SHA-256 of the rest (a pickled
string: plain numba reading such an index sees another version and
recompiles; it never unpickles the rest). A file is read once, its hash
checked, and only then unpickled; a file without a valid seal — damaged,
truncated, or written by something else — is never unpickled: it is removed
and the function compiled again (:func:`guard` counts them for the whole
copy before the first call, one line on the ``replay.kernels`` logger).

What this trusts: the owner's own files. The hashes detect damage (a bad
disk, a truncated write, a stray edit); they do not stop an attacker who
can write as the same user (who could as well edit the package). The
directory is kept owner-only (0700, files 0600); one writable by others is
made owner-only, one owned by another user is not used (:func:`private_dir`).
"""
from __future__ import annotations

import hashlib
import io
import logging
import os
import pickle
import stat
import uuid
from pathlib import Path

from numba.core.caching import Cache, IndexDataCacheFile

SEAL = "replay-sha256:"
_HEAD = len(pickle.dumps(SEAL + "0" * 64, protocol=4))  # the header's length: fixed
_log = logging.getLogger("replay.kernels")
_noted: set = set()


def _header(payload: bytes) -> bytes:
    return pickle.dumps(SEAL + hashlib.sha256(payload).hexdigest(), protocol=4)


def seal(payload: bytes) -> bytes:
    """``payload`` behind its SHA-256 header."""
    return _header(payload) + payload


def unseal(raw: bytes) -> bytes | None:
    """The payload of a sealed file, or None when its seal does not match (nothing unpickled)."""
    payload = raw[_HEAD:]
    return payload if len(raw) >= _HEAD and raw[:_HEAD] == _header(payload) else None


def write_private(path, data: bytes) -> None:
    """Write ``data`` to ``path`` owner-only (0600) and atomically: a crash leaves old or new."""
    path = str(path)
    tmp = f"{path}.tmp.{uuid.uuid4().hex[:16]}"
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


_counter = {"count": lambda n: None}  # set by guard(): binding's CACHE_REPORT counts damaged files


def _count(n: int, what: str) -> None:
    """Count ``n`` damaged files of ``what`` (removed); say it in one line."""
    _counter["count"](n)
    _log.warning("kernel cache: %d damaged file%s of %s removed and compiled again", n, "s" * (n != 1), what)


class SealedCacheFile(IndexDataCacheFile):
    """numba's index and data files of one function, written sealed and read only when the seal
    matches (the class of a copy's functions' ``_cache._cache_file``, set by :func:`guard`)."""

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
            for p in Path(self._cache_path).glob(self._index_name[:-len("nbi")] + "*.nbc"):
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
            note_once(f"kernel cache {os.path.dirname(path)}: cannot write ({e.strerror or e}); "
                      "compiled code not cached")


def note_once(msg: str) -> None:
    if msg not in _noted:
        _noted.add(msg)
        _log.warning(msg)


def _functions(module):
    from numba.core.dispatcher import Dispatcher

    return [v for v in vars(module).values()
            if isinstance(v, Dispatcher) and getattr(v.py_func, "__module__", None) == module.__name__]


def seal_cache(cache, label: str) -> None:
    """Make numba's ``cache`` of one function (a dispatcher's or cfunc's ``_cache``) sealed."""
    if isinstance(cache, Cache) and type(cache._cache_file) is IndexDataCacheFile:
        cache._cache_file.__class__ = SealedCacheFile
        cache._cache_file.label = label


def guard(module, label: str, count) -> int:
    """Seal the numba caches of the copy ``module``'s functions, and before any is called remove
    its numba cache files whose seal does not match (``count(n)``, one line). Returns how many."""
    _counter["count"] = count  # also for the damage found when a function is first called
    dirs = set()
    for fn in _functions(module):
        seal_cache(fn._cache, label)
        if isinstance(fn._cache, Cache):
            dirs.add(Path(fn._cache.cache_path))
    damaged = 0
    prefix = module.__name__ + "."
    for d in dirs:
        for p in sorted(d.glob(prefix + "*.nb[ic]"), key=lambda p: p.suffix != ".nbi"):  # indexes first
            try:
                raw = p.read_bytes()
                if unseal(raw) is None:
                    p.unlink()
                    damaged += 1
                    if p.suffix == ".nbi":  # its data files are orphans: removed unread
                        for q in d.glob(p.name[:-len("nbi")] + "*.nbc"):
                            q.unlink(missing_ok=True)
                elif p.stat().st_mode & 0o077:
                    p.chmod(0o600)
            except OSError:
                continue  # removed meanwhile by another process, or unreadable: numba's load skips it
    if damaged:
        _count(damaged, label)
    return damaged


def cfunc(sig, py, cached: bool, label: str = "a model"):
    """``numba.cfunc(sig, cache=cached)(py)`` with its cache sealed before it is read."""
    from numba.core import sigutils
    from numba.core.ccallback import CFunc

    res = CFunc(py, sigutils.normalize_signature(sig), locals={}, options={})
    if cached:
        res.enable_caching()
        seal_cache(res._cache, label)
    res.compile()
    return res


def private_dir(directory: Path, variable: str | None) -> str | None:
    """Make ``directory`` (and its ``__pycache__``) an owner-only directory of this user:
    None when done, else why it cannot be used (one line naming ``variable``, the environment
    variable the cache's root ``directory.parent`` came from, or the directory)."""
    if variable == "REPLAY_CACHE_DIR":
        where = f"{variable}={directory.parent}"
    else:
        where = f"kernel cache {directory}" + (f" (from {variable})" if variable else "")
    try:
        directory.mkdir(parents=True, exist_ok=True, mode=0o700)
        for d in (directory, directory / "__pycache__"):
            d.mkdir(mode=0o700, exist_ok=True)
            st = os.stat(d, follow_symlinks=False)
            if not stat.S_ISDIR(st.st_mode):
                return f"{where}: {d} is not a directory"
            if st.st_uid != os.getuid():
                return f"{where}: {d} belongs to another user"
            if st.st_mode & 0o077:
                os.chmod(d, 0o700)
                note_once(f"kernel cache {d}: was open to others; made owner-only (0700)")
        parent = os.stat(directory.parent)
        if parent.st_mode & 0o002 and not parent.st_mode & stat.S_ISVTX:
            return f"{where}: {directory.parent} is writable by anyone (no sticky bit)"
        probe = directory / f".probe.{os.getpid()}.{uuid.uuid4().hex[:8]}"
        probe.touch(mode=0o600)
        probe.unlink()
    except (FileExistsError, NotADirectoryError):
        culprit = next((p for p in (directory / "__pycache__", directory, *directory.parents)
                        if p.exists() and not p.is_dir()), directory)
        return f"{where}: " + ("not a directory" if culprit == directory.parent else f"{culprit} is not a directory")
    except OSError as e:
        return f"{where}: {e.strerror or e} (read-only or not writable)"
    return None
