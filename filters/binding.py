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
``replay.kernels`` logger. Older copies of the same model and template
(another digest) are removed with their numba cache files: the cache keeps one
copy per model and template. Two checkouts of different versions sharing one
cache directory therefore recompile each other's copies; give them separate
``REPLAY_CACHE_DIR``.
"""
from __future__ import annotations

import hashlib
import importlib.util
import inspect
import logging
import os
import sys
from pathlib import Path

from replay.util.errors import ReplayError

MARKER = "# MODEL KERNELS:"
CACHE_REPORT = {"rewritten": 0, "pruned": 0}  # copies of this process: rewritten (mismatch), removed (old)
_log = logging.getLogger("replay.kernels")


def cache_dir() -> Path:
    root = os.environ.get("REPLAY_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "replay")
    return Path(root) / "kernels"


def where(fn):
    """(module, name) of a module-level numba function."""
    py = getattr(fn, "py_func", None)
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
    model pruned (module docstring), and the names matching ``legacy`` (a regular expression)."""
    directory = cache_dir()
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.py"
    digest = name.rsplit("_", 1)[1]
    if not path.exists():
        _write(directory, name, text)
    elif not _matches(path, digest):
        _drop_numba_cache(directory, name)  # machine code compiled from the wrong text
        _write(directory, name, text)
        CACHE_REPORT["rewritten"] += 1
        _log.warning("kernel cache: %s did not match its hash; rewritten (compiled again)", path.name)
    _prune(directory, name, legacy)
    if not any((directory / "__pycache__").glob(f"{name}.*.nbi")):  # numba's index: none yet
        _log.info("compiling %s for %s (once per machine; cached for later runs)", what, label)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def _matches(path: Path, digest: str) -> bool:
    """Whether the file's content hashes to ``digest`` (the name's hash of the text)."""
    try:
        data = path.read_bytes()
    except OSError:
        return False
    return hashlib.sha256(data).hexdigest()[:len(digest)] == digest


def _write(directory: Path, name: str, text: str) -> None:
    tmp = directory / f".{name}.{os.getpid()}.tmp"
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, directory / f"{name}.py")  # atomic: concurrent processes write the same text


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
