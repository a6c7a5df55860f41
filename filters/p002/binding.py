"""The kernels of :mod:`replay.filters.p002.compiled` bound to one model's ``f``, ``h``, ``F``, ``H``.

``compiled.py`` calls the model's kernels as module globals. :func:`bind`
writes a copy of it with one model's imports at its MODEL KERNELS line and
imports that copy: numba then caches the compiled code on disk beside it, and
a new process loads it instead of compiling for about 20 s. (Passing the
kernels as function arguments instead works, but numba cannot cache such
signatures across processes.) The copy's name carries a hash of its text,
which includes the kernels' source files and ``compiled_util.py`` (the
model-free helpers it imports): a change to ``compiled.py``, to its helpers or
to a model's kernels gives a new copy and a fresh compilation, never stale machine
code. Copies live in ``$REPLAY_CACHE_DIR/kernels`` (default
``~/.cache/replay/kernels``). A model's kernels must be module-level
functions of an importable module.
"""
from __future__ import annotations

import hashlib
import importlib.util
import inspect
import os
import sys
from pathlib import Path

from replay.util.errors import ReplayError

MARKER = "# MODEL KERNELS:"
_bound: dict = {}


def cache_dir() -> Path:
    root = os.environ.get("REPLAY_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "replay")
    return Path(root) / "kernels"


def _where(fn):
    """(module, name) of a module-level numba function."""
    py = getattr(fn, "py_func", None)
    mod = sys.modules.get(py.__module__) if py is not None else None
    if mod is None or getattr(mod, py.__name__, None) is not fn:
        raise ReplayError(f"model kernel {fn!r} is not a module-level numba function of an importable module")
    return py.__module__, py.__name__


def bind(kernels):
    """The copy of :mod:`replay.filters.p002.compiled` bound to the model kernels ``(f, h, F, H)``."""
    key = tuple(id(k) for k in kernels)
    if key not in _bound:
        from . import compiled, compiled_util

        places = [_where(k) for k in kernels]
        lines = [f"from {mod} import {name} as {alias}  # noqa: E402"
                 for (mod, name), alias in zip(places, ("f", "h", "F", "H"))]
        kernel_sources = "".join(Path(inspect.getsourcefile(sys.modules[m])).read_text(encoding="utf-8")
                                 for m in sorted({m for m, _ in places}))
        digest = hashlib.sha256(kernel_sources.encode()).hexdigest()[:16]
        lines.append(f"# kernels' sources: sha256 {digest}")
        # numba's cache of this copy holds compiled_util's functions inlined but checks only this
        # file's stamp: the helpers' source in the name makes a change to them a new copy
        helpers = Path(inspect.getsourcefile(compiled_util)).read_text(encoding="utf-8")
        lines.append(f"# compiled_util: sha256 {hashlib.sha256(helpers.encode()).hexdigest()[:16]}")
        text = Path(inspect.getsourcefile(compiled)).read_text(encoding="utf-8")
        at = text.index(MARKER)
        end = text.index("\n", at)
        text = text[:at] + "\n".join(lines) + text[end:]
        name = "replay_compiled_" + hashlib.sha256(text.encode()).hexdigest()[:20]
        _bound[key] = _load(name, text)
    return _bound[key]


def _load(name: str, text: str):
    directory = cache_dir()
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.py"
    if not path.exists():
        tmp = directory / f".{name}.{os.getpid()}.tmp"
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)  # atomic: concurrent processes write the same text
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
