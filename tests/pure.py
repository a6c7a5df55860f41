"""The readable reference of a compiled kernel: its un-jitted ``py_func``, with every numba
function it calls un-jitted too (so the whole computation runs as Python)."""
from __future__ import annotations

import types

_done: dict = {}


def pure(fn):
    """``fn`` (a numba dispatcher or a Python function) as pure Python, recursively."""
    if id(fn) in _done:
        return _done[id(fn)]
    py = getattr(fn, "py_func", fn)
    g = dict(py.__globals__)
    out = types.FunctionType(py.__code__, g, py.__name__, py.__defaults__, py.__closure__)
    _done[id(fn)] = out
    for name, val in py.__globals__.items():
        if hasattr(val, "py_func") and callable(val):
            g[name] = pure(val)
    return out
