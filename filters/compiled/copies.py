"""Copies of a kernel template bound to one model's kernels ``f``, ``h``, ``F``, ``H``, cached on disk.

A template module (paper 002's :mod:`replay.filters.p002.compiled`, the run loops' rows forms
:mod:`replay.filters.compiled.rows`) calls the model's kernels as module globals. :func:`bind`
writes a copy of it with one model's imports at its MODEL KERNELS line and imports that copy:
numba then caches the compiled code on disk beside it, and a new process loads it instead of
compiling. (Passing the kernels as function arguments instead works, but numba cannot cache
such signatures across processes, and calls through function pointers are not inlined.)

The copy's name ``replay_<template>_<model>_<digest>`` carries a hash of where the model's
kernels live (``<model>``) and the SHA-256 of its text (``<digest>``); the text includes hashes
of the kernels' source files and of every project module whose functions the template or the
kernels call (found by following their globals: numba compiles those into the copy's cache but
checks only the copy's own file). A change to any of them gives a new copy and a fresh
compilation, never stale machine code. Copies live in ``$REPLAY_CACHE_DIR/kernels`` (default
``~/.cache/replay/kernels``). A model's kernels must be module-level functions of an
importable module.

The cache is checked before it is imported (:func:`load`): a copy whose content does not hash
to its name (edited, truncated, another version's) is written again and its numba cache
(``__pycache__/<name>.*``) removed, so it is compiled afresh, counted in :data:`.files.CACHE_REPORT`
and noted once on the ``replay.kernels`` logger. A copy is executed from its verified text (no
byte-code file is read), and numba's cache files of its functions are sealed and checked before
they are unpickled (:mod:`.numba_internals`). A directory that cannot be used means compiling in
memory, nothing cached (:func:`.files.private_dir`). Older copies of the same model and template
(another digest) are removed with their numba cache files: the cache keeps one copy per model
and template. Two checkouts of different versions sharing one cache directory therefore
recompile each other's copies; give them separate ``REPLAY_CACHE_DIR``.
"""

from __future__ import annotations

import hashlib
import inspect
import sys
import types
from pathlib import Path

from replay.util.errors import ReplayError

from . import files, numba_internals
from .files import cache_dir, log, note_once, private_dir, write_private

MARKER = "# MODEL KERNELS:"
_bound: dict = {}  # (template, kernels) -> the imported copy


def bind(template, kernels, what: str = "kernels"):
    """The copy of the module ``template`` bound to the model kernels ``(f, h, F, H)``, imported
    (once per process); ``what`` says what its one-time compilation is."""
    key = (template.__name__, tuple(id(k) for k in kernels))
    if key not in _bound:
        _bound[key] = _bound_copy(template, kernels, what)
    return _bound[key]


def where(fn):
    """(module, name) of a module-level numba function (a Python function when numba's JIT is disabled)."""
    py = getattr(fn, "py_func", fn if numba_internals.jit_disabled() else None)
    mod = sys.modules.get(py.__module__) if py is not None else None
    if mod is None or getattr(mod, py.__name__, None) is not fn:
        raise ReplayError(f"model kernel {fn!r} is not a module-level numba function of an importable module")
    return py.__module__, py.__name__


def _source(module) -> str:
    return Path(inspect.getsourcefile(module)).read_text(encoding="utf-8")


def _callees(modules) -> list:
    """The modules whose functions ``modules`` call, and theirs, and so on (not ``modules``): those of
    this project and of the packages ``modules`` belong to (a plugin's), not third-party libraries."""
    seen, todo = {m.__name__ for m in modules}, list(modules)
    roots = {"replay"} | {m.__name__.split(".")[0] for m in modules}
    found = []
    while todo:
        for v in list(vars(todo.pop()).values()):
            py = getattr(v, "py_func", v)  # a numba function, or a Python one (also with the JIT disabled)
            name = py.__module__ if inspect.isfunction(py) else ""
            if name.split(".")[0] in roots and name not in seen and name in sys.modules:
                seen.add(name)
                found.append(sys.modules[name])
                todo.append(sys.modules[name])
    return sorted(found, key=lambda m: m.__name__)


def _bound_copy(template, kernels, what: str):
    places = [where(k) for k in kernels]
    lines = [
        f"from {mod} import {name} as {alias}  # noqa: E402" for (mod, name), alias in zip(places, ("f", "h", "F", "H"))
    ]
    kernel_modules = [sys.modules[m] for m in sorted({m for m, _ in places})]
    for tag, mods in (
        ("kernels' sources", kernel_modules),
        ("the functions they call", _callees([template, *kernel_modules])),
    ):
        text = "".join(_source(m) for m in mods)
        lines.append(f"# {tag}: sha256 {hashlib.sha256(text.encode()).hexdigest()[:16]}")
    lines.append("# numba's cache files of this copy are sealed (replay.filters.compiled.numba_internals, format 1)")
    text = _source(template)
    at = text.index(MARKER)
    text = text[:at] + "\n".join(lines) + text[text.index("\n", at) :]
    model = hashlib.sha256(repr(places).encode()).hexdigest()[:8]
    label = ", ".join(sorted({m.rsplit(".", 1)[-1].removesuffix("_kernels") for m, _ in places}))
    prefix = f"replay_{template.__name__.rsplit('.', 1)[-1]}_"
    return load(f"{prefix}{model}_{hashlib.sha256(text.encode()).hexdigest()[:20]}", text, label, what)


def load(name: str, text: str, label: str = "a model", what: str = "kernels"):
    """Import the copy ``name`` (``<prefix><model>_<digest>``) holding ``text``: written when
    absent, written again when its content does not hash to ``<digest>``; older copies of the
    model pruned (module docstring). Its numba cache files are checked before any is read
    (:func:`.numba_internals.guard`). A cache directory that cannot be used (a file, read-only,
    another user's): compiled in memory, nothing written (one note)."""
    directory = cache_dir()
    why = private_dir(directory)
    path = directory / f"{name}.py"
    try:
        if why is None and not _matches(path, name.rsplit("_", 1)[1]):
            wrong = path.exists()
            if wrong:  # machine code compiled from the wrong text
                _drop_numba_cache(directory, name)
                files.CACHE_REPORT["rewritten"] += 1
                log.warning("kernel cache: %s did not match its hash; rewritten (compiled again)", path.name)
            # atomic; an absent copy is written by the first of concurrent processes only, so that all
            # see one file time (numba's index is valid for its source file's time and size only)
            write_private(path, text.encode("utf-8"), replace=wrong)
    except OSError as e:  # e.g. a full disk
        why = f"kernel cache {directory}: cannot write {path.name} ({e.strerror or e})"
    if why is not None:  # the templates' decorators without numba's disk cache: same machine code
        note_once(f"{why}; kernels compiled in memory for this process, not cached")
        log.info("compiling %s for %s (in memory)", what, label)
        return _exec(name, text.replace("cache=True", "cache=False"), f"<replay kernels {name}>")
    _prune(directory, name)
    if not any((directory / "__pycache__").glob(f"{name}.*.nbi")):  # numba's index: none yet
        log.info("compiling %s for %s (one time, cached for later runs)...", what, label)
    module = _exec(name, text, str(path))  # the verified text: no byte-code file read
    module.LABEL = label
    numba_internals.guard(module, label)
    return module


def _exec(name: str, text: str, filename: str):
    """The module ``name`` executed from ``text`` (registered in ``sys.modules``: numba finds its
    functions there), its functions' source file ``filename``."""
    module = types.ModuleType(name)
    module.__file__ = filename
    module.CACHED = not filename.startswith("<")
    sys.modules[name] = module
    exec(compile(text, filename, "exec"), module.__dict__)
    return module


def cfunc(fty, fn):
    """A cfunc of the copy's function ``fn`` (a dispatcher) of the first-class function type ``fty``,
    cached (sealed) beside the copy when it is; with numba's JIT disabled ``fn`` itself."""
    if numba_internals.jit_disabled():
        return fn
    mod = sys.modules.get(fn.py_func.__module__)
    return numba_internals.cfunc(fty, fn.py_func, getattr(mod, "CACHED", False), getattr(mod, "LABEL", "a model"))


def _matches(path: Path, digest: str) -> bool:
    """Whether the file's content hashes to ``digest`` (the name's hash of the text)."""
    try:
        data = path.read_bytes()
    except OSError:
        return False
    return hashlib.sha256(data).hexdigest()[: len(digest)] == digest


def _drop_numba_cache(directory: Path, name: str) -> None:
    """Remove numba's cache (index, machine code) and the bytecode of copy ``name``."""
    for p in (directory / "__pycache__").glob(name + ".*"):
        p.unlink(missing_ok=True)


def _prune(directory: Path, current: str) -> None:
    """Remove the other copies of ``current``'s model and template (another digest), with their numba caches."""
    for p in directory.glob(f"{current[: current.rindex('_') + 1]}*.py"):
        if p.stem != current:
            p.unlink(missing_ok=True)
            _drop_numba_cache(directory, p.stem)
            files.CACHE_REPORT["pruned"] += 1
