"""Copies of a kernel template bound to one model's kernels ``f``, ``h``, ``F``, ``H``, cached on disk.

A template module (paper 002's :mod:`replay.filters.p002.compiled`, the run
loops' rows forms :mod:`replay.filters.rows`) calls the model's kernels as
module globals. :func:`bound_copy` writes a copy of it with one model's
imports at its MODEL KERNELS line and imports that copy: numba then caches the
compiled code on disk beside it, and a new process loads it instead of
compiling. (Passing the kernels as function arguments instead works, but
numba cannot cache such signatures across processes, and calls through
function pointers are not inlined.) The copy's name carries a hash of its
text, which includes the kernels' source files and the model-free helpers the
template imports: a change to the template, to its helpers or to a model's
kernels gives a new copy and a fresh compilation, never stale machine code.
Copies live in ``$REPLAY_CACHE_DIR/kernels`` (default
``~/.cache/replay/kernels``). A model's kernels must be module-level functions
of an importable module.

The cache is checked before it is imported (:func:`load`): a copy is named
``<prefix><model>_<digest>``, ``<model>`` a hash of where the model's kernels
live and ``<digest>`` the SHA-256 of the copy's text; a copy whose content
does not hash to its name (edited, truncated, another version's) is written
again and its numba cache (``__pycache__/<name>.*``) removed, so it is
compiled afresh — counted in :data:`CACHE_REPORT` and noted once on the
``replay.kernels`` logger. A copy is executed from its verified text (no
byte-code file is read), and numba's cache files of its functions are sealed
and checked before they are unpickled (:mod:`replay.filters.kernel_files`,
which also keeps the directory owner-only; a directory that cannot be used
means compiling in memory, nothing cached). Older copies of the same model and template
(another digest) are removed with their numba cache files: the cache keeps one
copy per model and template. Two checkouts of different versions sharing one
cache directory therefore recompile each other's copies; give them separate
``REPLAY_CACHE_DIR``.
"""
from __future__ import annotations

import hashlib
import inspect
import logging
import os
import sys
import types
from pathlib import Path

from replay.util.errors import ReplayError

MARKER = "# MODEL KERNELS:"
CACHE_REPORT = {"rewritten": 0, "pruned": 0, "damaged": 0}  # this process: copies rewritten (mismatch), removed
# (old), numba cache files removed (seal did not match)
_log = logging.getLogger("replay.kernels")


def cache_dir() -> Path:
    root = os.environ.get("REPLAY_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or "~/.cache", "replay")
    return Path(root).expanduser() / "kernels"


def where(fn):
    """(module, name) of a module-level numba function (a Python function when numba's JIT is disabled)."""
    from numba.core import config

    py = getattr(fn, "py_func", fn if config.DISABLE_JIT else None)
    mod = sys.modules.get(py.__module__) if py is not None else None
    if mod is None or getattr(mod, py.__name__, None) is not fn:
        raise ReplayError(f"model kernel {fn!r} is not a module-level numba function of an importable module")
    return py.__module__, py.__name__


def _source(module) -> str:
    return Path(inspect.getsourcefile(module)).read_text(encoding="utf-8")


def bound_copy(template, kernels, helpers, prefix: str, what: str, helpers_tag: str = "helpers", legacy=None):
    """The copy of the module ``template`` bound to the model kernels ``(f, h, F, H)``, imported:
    ``helpers`` the model-free modules whose functions numba inlines into it (their source is
    part of the copy's text, so a change to them makes a new copy), ``prefix`` the copies' names,
    ``what`` how the compilation is announced."""
    places = [where(k) for k in kernels]
    lines = [f"from {mod} import {name} as {alias}  # noqa: E402"
             for (mod, name), alias in zip(places, ("f", "h", "F", "H"))]
    kernel_sources = "".join(_source(sys.modules[m]) for m in sorted({m for m, _ in places}))
    lines.append(f"# kernels' sources: sha256 {hashlib.sha256(kernel_sources.encode()).hexdigest()[:16]}")
    # numba's cache of this copy holds the helpers' functions inlined but checks only this
    # file's stamp: the helpers' source in the name makes a change to them a new copy
    lines.append("# numba's cache files of this copy are sealed (replay.filters.kernel_files, format 1)")  # a new
    # format, a new name: the former unsealed files are pruned unread, not counted as damaged
    text = "".join(_source(m) for m in helpers)
    lines.append(f"# {helpers_tag}: sha256 {hashlib.sha256(text.encode()).hexdigest()[:16]}")
    text = _source(template)
    at = text.index(MARKER)
    end = text.index("\n", at)
    text = text[:at] + "\n".join(lines) + text[end:]
    model = hashlib.sha256(repr(places).encode()).hexdigest()[:8]
    label = ", ".join(sorted({m.rsplit(".", 1)[-1].removesuffix("_kernels") for m, _ in places}))
    return load(f"{prefix}{model}_{hashlib.sha256(text.encode()).hexdigest()[:20]}", text, label, what, legacy)


def load(name: str, text: str, label: str = "a model", what: str = "kernels", legacy=None):
    """Import the copy ``name`` (``<prefix><model>_<digest>``) holding ``text``: written when
    absent, written again when its content does not hash to ``<digest>``; older copies of the
    model pruned (module docstring), and the names matching ``legacy`` (a regular expression).
    Its numba cache files are checked before any is read (:func:`replay.filters.kernel_files.guard`).
    A cache directory that cannot be used (a file, read-only, another user's): compiled in memory,
    nothing written (one note)."""
    from . import kernel_files

    directory = cache_dir()
    why = kernel_files.private_dir(directory, next((v for v in ("REPLAY_CACHE_DIR", "XDG_CACHE_HOME")
                                                    if os.environ.get(v)), None))
    path = directory / f"{name}.py"
    digest = name.rsplit("_", 1)[1]
    try:
        if why is None and not path.exists():
            _write(directory, name, text)
        elif why is None and not _matches(path, digest):
            _drop_numba_cache(directory, name)  # machine code compiled from the wrong text
            _write(directory, name, text)
            CACHE_REPORT["rewritten"] += 1
            _log.warning("kernel cache: %s did not match its hash; rewritten (compiled again)", path.name)
    except OSError as e:  # e.g. a full disk
        why = f"kernel cache {directory}: cannot write {path.name} ({e.strerror or e})"
    if why is not None:  # the templates' decorators without numba's disk cache: same machine code
        kernel_files.note_once(f"{why}; kernels compiled in memory for this process, not cached")
        _log.info("compiling %s for %s (in memory)", what, label)
        return _exec(name, text.replace("cache=True", "cache=False"), f"<replay kernels {name}>")
    _prune(directory, name, legacy)
    if not any((directory / "__pycache__").glob(f"{name}.*.nbi")):  # numba's index: none yet
        _log.info("compiling %s for %s (one time, cached for later runs)...", what, label)
    module = _exec(name, text, str(path))  # the verified text: no byte-code file read
    module.LABEL = label
    kernel_files.guard(module, label, _count_damaged)
    return module


def _count_damaged(n: int) -> None:
    CACHE_REPORT["damaged"] = CACHE_REPORT.get("damaged", 0) + n


def _exec(name: str, text: str, filename: str):
    """The module ``name`` executed from ``text`` (registered in ``sys.modules``: numba finds its
    functions there), its functions' source file ``filename``."""
    module = types.ModuleType(name)
    module.__file__ = filename
    module.CACHED = not filename.startswith("<")
    sys.modules[name] = module
    exec(compile(text, filename, "exec"), module.__dict__)
    return module


def cfunc(sig, fn):
    """A cfunc of the copy's function ``fn`` (a dispatcher), cached (sealed) beside the copy when it is;
    with numba's JIT disabled ``fn`` itself (a Python function)."""
    from . import kernel_files

    if not hasattr(fn, "py_func"):
        return fn
    mod = sys.modules.get(fn.py_func.__module__)
    return kernel_files.cfunc(sig, fn.py_func, getattr(mod, "CACHED", False), getattr(mod, "LABEL", "a model"))


def _matches(path: Path, digest: str) -> bool:
    """Whether the file's content hashes to ``digest`` (the name's hash of the text)."""
    try:
        data = path.read_bytes()
    except OSError:
        return False
    return hashlib.sha256(data).hexdigest()[:len(digest)] == digest


def _write(directory: Path, name: str, text: str) -> None:
    from .kernel_files import write_private

    write_private(directory / f"{name}.py", text.encode("utf-8"))  # atomic: concurrent processes write the same text


def _drop_numba_cache(directory: Path, name: str) -> int:
    """Remove numba's cache (index, machine code) and the bytecode of copy ``name``."""
    n = 0
    cache = directory / "__pycache__"
    if cache.is_dir():
        for p in cache.iterdir():
            if p.name.startswith(name + "."):
                p.unlink(missing_ok=True)
                n += 1
    return n


def _prune(directory: Path, current: str, legacy=None) -> None:
    """Remove the other copies of ``current``'s model and template (another digest), and the
    copies whose names match ``legacy``, with their numba caches."""
    model = current[:current.rindex("_") + 1]
    for p in directory.glob(f"{model}*.py"):
        stem = p.stem
        if stem != current:
            p.unlink(missing_ok=True)
            _drop_numba_cache(directory, stem)
            CACHE_REPORT["pruned"] += 1
    for p in directory.glob("*.py") if legacy is not None else ():
        stem = p.stem
        if stem != current and legacy.match(stem):
            p.unlink(missing_ok=True)
            _drop_numba_cache(directory, stem)
            CACHE_REPORT["pruned"] += 1
