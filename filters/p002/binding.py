"""The kernels of :mod:`replay.filters.p002.compiled` bound to one model's ``f``, ``h``, ``F``, ``H``
(the mechanism: :mod:`replay.filters.binding`).

``compiled.py`` calls the model's kernels as module globals. :func:`bind`
writes a copy of it with one model's imports at its MODEL KERNELS line and
imports that copy: numba then caches the compiled code on disk beside it, and
a new process loads it instead of compiling for about 20 s. (Passing the
kernels as function arguments instead works, but numba cannot cache such
signatures across processes.) The copy's name carries a hash of its text,
which includes the kernels' source files and ``compiled_util.py``,
``replay/filters/particles.py`` and ``replay/util/kernels.py`` (the model-free
helpers it imports): a change to ``compiled.py``, to its helpers or
to a model's kernels gives a new copy and a fresh compilation, never stale machine
code. Copies live in ``$REPLAY_CACHE_DIR/kernels`` (default
``~/.cache/replay/kernels``). A model's kernels must be module-level
functions of an importable module.

The cache is checked before it is imported (:func:`_load`): a copy is named
``replay_compiled_<model>_<digest>``, ``<model>`` a hash of where the model's
kernels live and ``<digest>`` the SHA-256 of the copy's text; a copy whose
content does not hash to its name (edited, truncated, another version's) is
written again and its numba cache (``__pycache__/<name>.*``) removed, so it
is compiled afresh — counted in :data:`CACHE_REPORT` and noted once on the
``replay.kernels`` logger; numba's cache files beside it are sealed with their
SHA-256 and checked before they are unpickled (:mod:`replay.filters.kernel_files`).
Older copies of the same model (another digest, or
the former ``replay_compiled_<digest>`` names) are removed with their numba
cache files: the cache keeps one copy per model. Two checkouts of different
versions sharing one cache directory therefore recompile each other's copies;
give them separate ``REPLAY_CACHE_DIR``.
"""
from __future__ import annotations

import re

from replay.filters.binding import CACHE_REPORT, MARKER, bound_copy, cache_dir, load  # noqa: F401

PREFIX = "replay_compiled_"
LEGACY = re.compile(r"^replay_compiled_[0-9a-f]{20}$")  # names before the model key
_bound: dict = {}
WHAT = "the paper-002 filter kernels (about 20-40 s)"


def bind(kernels):
    """The copy of :mod:`replay.filters.p002.compiled` bound to the model kernels ``(f, h, F, H)``."""
    key = tuple(id(k) for k in kernels)
    if key not in _bound:
        from replay.filters import particles
        from replay.util import kernels as util_kernels

        from . import compiled, compiled_util

        _bound[key] = bound_copy(compiled, kernels, (compiled_util, particles, util_kernels), PREFIX, WHAT,
                                 helpers_tag="compiled_util", legacy=LEGACY)
    return _bound[key]


def _load(name: str, text: str, label: str = "a model"):
    """:func:`replay.filters.binding.load` for paper 002's copies."""
    return load(name, text, label, WHAT, LEGACY)
