"""numba's disk cache of replay's compiled functions, safe for any number of processes and checked
before anything in it is unpickled (numba is pinned to 0.68 in pyproject.toml).

numba keeps a function's machine code as pickles: an index (``<function>.nbi``: signature ->
data file) and one data file per signature (``.nbc``), beside the source (``__pycache__``) or
under ``NUMBA_CACHE_DIR``; a bound copy's beside it in ``$REPLAY_CACHE_DIR/kernels``. Unpickling
a file runs code, and machine code loaded for the wrong signature crashes the process. So, for
every function of replay (a module ``replay.*``, or a bound copy ``replay_*``), once this module
is imported (every module with ``cache=True`` functions imports it first, checked by a test):

* **One writer, no reader in between.** A save reads the index, takes the signature's data file
  (or the first free number), writes the data, then the index, under an exclusive ``flock`` of
  ``<index>.lock``; a load reads the index and the data file under a shared one. (numba's own
  save holds no lock and writes the index first: concurrent cold starts left an index naming one
  signature beside another signature's code, a segfault on every later load.) Functions of other
  packages get the same lock around numba's own load and save, their files unchanged.
* **Sealed with a key, and bound to their signature.** Each file starts with a fixed-length
  header holding the HMAC-SHA-256 of the rest under this user's cache key (:func:`key_path`: a
  random 32-byte file, owner-only, created on first use, outside every cache directory), and a
  data file holds the signature it was compiled for. A file is read once, its seal checked, and
  only then unpickled; a file without a valid seal (damaged, truncated, written by plain numba,
  by another user or on another machine, or forged by anyone who cannot read the key) is never
  unpickled: it is removed and the function compiled again (counted in :data:`CACHE_REPORT`, one
  line on the ``replay.kernels`` logger). A data file naming another signature than the index
  says is not executed either: the function is compiled and the entry written again.
* **Bound to every compiled source.** numba keys an index on its function's file alone (a loop cached
  before an edit or upgrade of a kernel it calls would run the old one): an index also holds
  :func:`sources_digest`; any change there compiles everything again.
  Not stopped: whoever reads the key file (this user, root), who can change the code too. Without
  a usable key nothing is loaded from or written to these caches (one note): every process compiles.
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import importlib.util
import io
import itertools
import logging
import os
import pickle
import stat
import time
import uuid
from contextlib import contextmanager
from pathlib import Path

from numba.core.caching import Cache, IndexDataCacheFile
from numba.np.ufunc.wrappers import _GufuncWrapper

log = logging.getLogger("replay.kernels")
CACHE_REPORT = {"rewritten": 0, "pruned": 0, "damaged": 0}  # this process: copies rewritten (did not match
# their hash), removed (old), numba cache files removed (seal did not match, or data of another signature)
_noted: set = set()

SEAL = "replay-hmac:"
_HEAD = len(pickle.dumps(SEAL + "0" * 64, protocol=4))  # the header's length: fixed
KEY_BYTES = 32
LOCK_WAIT = 30.0  # s: longest wait for another process's write of one function's cache


def note_once(msg: str) -> None:
    if msg not in _noted:
        _noted.add(msg)
        log.warning(msg)


def write_private(path, data: bytes, replace: bool = True) -> None:
    """Write ``data`` to ``path`` owner-only (0600) and atomically: a crash leaves old or new.
    ``replace=False``: only when ``path`` does not exist (the first of concurrent writers wins)."""
    path = str(path)
    tmp = f"{path}.tmp.{uuid.uuid4().hex[:16]}"
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        if replace:
            os.replace(tmp, path)
        else:
            try:
                os.link(tmp, path)
            except FileExistsError:
                pass
            os.unlink(tmp)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


# ------------------------------------------------------------------------------------ the key


def cache_root() -> Path:
    """``$REPLAY_CACHE_DIR`` (default ``$XDG_CACHE_HOME/replay``, ``~/.cache/replay``)."""
    root = os.environ.get("REPLAY_CACHE_DIR") or os.path.join(os.environ.get("XDG_CACHE_HOME") or "~/.cache", "replay")
    return Path(root).expanduser()


def key_path() -> Path:
    """``$REPLAY_CACHE_KEY`` (a file), default ``$XDG_CONFIG_HOME/replay/cache-key`` (``~/.config/...``)."""
    given = os.environ.get("REPLAY_CACHE_KEY")
    if given:
        return Path(given).expanduser()
    return Path(os.environ.get("XDG_CONFIG_HOME") or "~/.config").expanduser() / "replay" / "cache-key"


_keys: dict = {}  # key file -> its bytes, or None (unusable: noted)


def _problem(path: Path) -> str | None:
    """Why the key file ``path`` cannot be trusted, or None."""
    if path.resolve().is_relative_to(cache_root().resolve()):
        return "it is inside the cache directory it seals (anyone who can write the cache could read it)"
    st = os.stat(path, follow_symlinks=False)
    if not stat.S_ISREG(st.st_mode):
        return "not a regular file"
    if st.st_uid != os.getuid():
        return "it belongs to another user"
    if st.st_mode & 0o077:
        return "it is readable or writable by others (make it 0600)"
    if st.st_size != KEY_BYTES:
        return f"it is not {KEY_BYTES} bytes long"
    return None


def cache_key() -> bytes | None:
    """This user's cache key (:func:`key_path`), created on first use; None (one note) when unusable."""
    path = key_path()
    if path in _keys:
        return _keys[path]
    key = why = None
    try:
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
            write_private(path, os.urandom(KEY_BYTES), replace=False)  # concurrent first uses: one key
        why = _problem(path)
        if why is None:
            key = path.read_bytes()
    except OSError as e:
        why = f"cannot be created or read ({e.strerror or e})"
    if why is not None:
        note_once(
            f"kernel cache key {path}: {why}; compiled kernels are not cached (set REPLAY_CACHE_KEY to another file)"
        )
    _keys[path] = key
    return key


def _header(payload: bytes, key: bytes) -> bytes:
    return pickle.dumps(SEAL + hmac.new(key, payload, hashlib.sha256).hexdigest(), protocol=4)


def seal(payload: bytes, key: bytes | None = None) -> bytes:
    """``payload`` behind its HMAC header (this user's key unless ``key``)."""
    return _header(payload, key or cache_key()) + payload


def unseal(raw: bytes, key: bytes | None = None) -> bytes | None:
    """The payload of a sealed file, or None when its seal does not match this user's key (nothing unpickled)."""
    key = key or cache_key()
    if key is None or len(raw) < _HEAD:
        return None
    payload = raw[_HEAD:]
    return payload if hmac.compare_digest(raw[:_HEAD], _header(payload, key)) else None


def count(n: int, what: str) -> None:
    """Count ``n`` damaged files of ``what`` (removed); say it in one line."""
    CACHE_REPORT["damaged"] += n
    log.warning("kernel cache: %d damaged file%s of %s removed and compiled again", n, "s" * (n != 1), what)


# ------------------------------------------------------------------------------------ the lock


@contextmanager
def index_lock(index_path: str, exclusive: bool = True):
    """A ``flock`` on ``<index>.lock`` (exclusive, or shared for readers) while the block runs, waited
    for at most :data:`LOCK_WAIT` (then, or where there is no ``flock`` or no directory yet, the block
    runs unlocked, as numba's own load and save do)."""
    try:
        # lazy: POSIX only (no fcntl on Windows: the block runs unlocked)
        import fcntl  # noqa: PLC0415

        fd = os.open(index_path + ".lock", os.O_CREAT | os.O_RDWR, 0o600)
    except (ImportError, OSError):
        fd = None
    try:
        end = time.monotonic() + LOCK_WAIT
        while fd is not None:
            try:
                fcntl.flock(fd, (fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH) | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > end:
                    break
                time.sleep(0.005)
        yield
    finally:
        if fd is not None:
            os.close(fd)  # releases the lock


def _free(self, entries: dict, key):
    """The data file of ``key``: its own, or the first number no entry uses."""
    name = entries.get(key)
    if name is None:
        used = set(entries.values())
        name = next(n for n in map(self._data_name, itertools.count(1)) if n not in used)
    return name


def locked_save(self, key, data):
    """numba's ``IndexDataCacheFile.save`` as one critical section per function (:func:`index_lock`):
    read the index, take the key's data file, write the data, then the index that names it. The
    files' format is numba's, so processes without this still read them."""
    with index_lock(self._index_path):
        entries = self._load_index()
        name = _free(self, entries, key)
        self._save_data(name, data)
        if entries.get(key) != name:
            entries[key] = name
            self._save_index(entries)


def locked_load(self, key):
    """numba's ``IndexDataCacheFile.load`` under a shared lock: never between a writer's data and index."""
    with index_lock(self._index_path, exclusive=False):
        return NUMBA_LOAD(self, key)


def _remove(path) -> None:
    """Remove a file not to be read (a read-only cache: left, and never read either)."""
    try:
        Path(path).unlink(missing_ok=True)
    except OSError:
        pass


SOURCES = ("filters", "replay/models", "replay/util", "replay/model.py", "replay/scoring/metrics.py")  # compiled code


def source_files() -> list[tuple[str, Path]]:
    """(name, path) of every source of compiled code (:data:`SOURCES`); ``filters`` where Python
    imports ``replay.filters`` from (a checkout maps it beside ``replay/``)."""
    here = Path(__file__).resolve().parents[1]  # the replay package
    spec = importlib.util.find_spec("replay.filters")
    roots = {"filters": Path(next(iter(spec.submodule_search_locations))) if spec else here / "filters"}
    out = []
    for name in SOURCES:
        top = roots.get(name, here.parent / name)
        if top.is_dir():
            out += [(f"{name}/{f.relative_to(top).as_posix()}", f) for f in sorted(top.rglob("*.py"))]
        elif top.is_file():
            out.append((name, top))
    return out


@functools.cache
def sources_digest() -> str:
    """SHA-256 over the names and contents of :func:`source_files`, once per process."""
    h = hashlib.sha256()
    for name, f in source_files():
        h.update(name.encode() + b"\0" + hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


class SealedCacheFile(IndexDataCacheFile):
    """numba's index and data files of one function of replay, sealed, locked and bound to their
    signature (module docstring); the class of its cache file once :func:`adopt` saw it."""

    label = "a model"  # named in the note

    def _read_sealed(self, path) -> bytes | None:
        with open(path, "rb") as f:
            raw = f.read()
        payload = unseal(raw)
        if payload is None and cache_key() is not None:  # damaged: never unpickled; removed, compiled again
            _remove(path)
            count(1, self.label)
        return payload

    def _load_index(self):
        try:
            payload = self._read_sealed(self._index_path)
        except OSError:  # absent (or unreadable): nothing cached
            return {}
        if payload is None:  # its data files are orphans now: removed, or a new index could name them
            if cache_key() is not None:
                for p in Path(self._cache_path).glob(self._index_name[: -len("nbi")] + "*.nbc"):
                    _remove(p)
            return {}
        f = io.BytesIO(payload)
        if pickle.load(f) != self._version:
            return {}
        stamp, entries = pickle.loads(f.read())
        return entries if stamp == (self._source_stamp, sources_digest()) else {}

    def _save_index(self, entries):
        f = io.BytesIO()
        pickle.dump(self._version, f, protocol=-1)
        f.write(self._dump(((self._source_stamp, sources_digest()), entries)))
        self._write(self._index_path, f.getvalue())

    def save(self, key, data):
        if cache_key() is None:
            return
        with index_lock(self._index_path):
            entries = self._load_index()
            name = _free(self, entries, key)
            self._write(self._data_path(name), self._dump((key, data)))  # the data names its signature
            if entries.get(key) != name:
                entries[key] = name
                self._save_index(entries)

    def load(self, key):
        if cache_key() is None:
            return None
        with index_lock(self._index_path, exclusive=False):
            name = self._load_index().get(key)
            if name is None:
                return None
            try:
                payload = self._read_sealed(self._data_path(name))
            except OSError:  # removed meanwhile: compiled
                return None
        if payload is None:
            return None
        saved, data = pickle.loads(payload)
        if saved != key:  # another signature's code under this one's name: never executed
            count(1, self.label)
            return None
        return data

    def _write(self, path, payload: bytes) -> None:
        try:
            write_private(path, seal(payload))
        except OSError as e:  # e.g. a full disk: the compiled code runs, only not cached
            note_once(
                f"kernel cache {os.path.dirname(path)}: cannot write ({e.strerror or e}); compiled code not cached"
            )


def ours(module: str) -> bool:
    """Whether functions of ``module`` are replay's (its package, or a bound copy ``replay_*``)."""
    return module == "replay" or module.startswith(("replay.", "replay_"))


def adopt(cache, label: str | None = None) -> None:
    """Make numba's ``cache`` of one of replay's functions (a dispatcher's, gufunc's or cfunc's) sealed."""
    if isinstance(cache, Cache) and type(cache._cache_file) is IndexDataCacheFile:
        cache._cache_file.__class__ = SealedCacheFile
        if label is None:
            mod = getattr(cache._py_func, "__module__", "") or ""
            label = mod.rsplit(".", 1)[-1].removesuffix("_kernels")
        cache._cache_file.label = label


def _adopting(method):
    def wrapped(self, sig, *args):
        if type(self._cache_file) is IndexDataCacheFile and ours(getattr(self._py_func, "__module__", "") or ""):
            adopt(self)
        return method(self, sig, *args)

    return wrapped


def _paired_wrapper(self, wrapper_name):
    """numba's ``_GufuncWrapper._compile_wrapper`` (a gufunc's loop, cached under its signature only),
    checked: the cached loop calls its kernel by a name holding the compiling process's function
    counter, so a loop cached by one process beside a kernel compiled by another (concurrent cold
    starts) names a function this process does not have: a null pointer, a segfault on every later
    call. Such a loop is built again here (and its cache entry replaced), never called."""
    lib = _GufuncWrapper.numba_compile_wrapper(self, wrapper_name)
    if self.is_parfors or lib.get_pointer_to_function(wrapper_name):
        return lib
    count(1, getattr(self.py_func, "__name__", "a gufunc") + "'s array form (a loop of another compilation)")
    lib = self.context.codegen().create_library(str(self))
    lib.enable_object_caching()
    self._build_wrapper(lib, wrapper_name)
    self.cache.save_overload(self.cres.signature, lib)
    return lib


if not hasattr(IndexDataCacheFile, "numba_save"):  # numba's own methods, kept once per process (a reload too)
    IndexDataCacheFile.numba_save, IndexDataCacheFile.numba_load = IndexDataCacheFile.save, IndexDataCacheFile.load
    Cache.numba_load_overload, Cache.numba_save_overload = Cache.load_overload, Cache.save_overload
    _GufuncWrapper.numba_compile_wrapper = _GufuncWrapper._compile_wrapper
NUMBA_SAVE, NUMBA_LOAD = IndexDataCacheFile.numba_save, IndexDataCacheFile.numba_load  # (the tests' control)
IndexDataCacheFile.save, IndexDataCacheFile.load = locked_save, locked_load
Cache.load_overload = _adopting(Cache.numba_load_overload)
Cache.save_overload = _adopting(Cache.numba_save_overload)
_GufuncWrapper._compile_wrapper = _paired_wrapper
