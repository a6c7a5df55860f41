"""Named plugins: the registries of filters, tasks, adapters and reproductions map
a name to ``"module:attribute"``; modules are imported only when used.

The registries of filters, tasks and adapters are :class:`replay.util.plugins.Registry`
objects: besides their built-in entries they hold the entry points of other installed
distributions and resolve ``"module:Class"`` names; :func:`resolve` defers to them.
"""
from __future__ import annotations

from importlib import import_module

from replay.util.errors import ReplayError


def resolve(table, name: str, kind: str):
    """The object registered as ``name`` in ``table``; unknown names -> one-line ReplayError."""
    if hasattr(table, "load"):  # a plugin registry (replay.util.plugins.Registry)
        return table.load(name)
    try:
        module, attr = table[name].split(":")
    except KeyError:
        raise ReplayError(f"unknown {kind} {name!r} (known: {', '.join(sorted(table))})") from None
    return getattr(import_module(module), attr)


def instantiate(table, name: str, kind: str, **params):
    """``resolve(...)(**params)``; a wrong parameter name -> one-line ReplayError."""
    cls = resolve(table, name, kind)
    try:
        return cls(**params)
    except TypeError as err:
        raise ReplayError(f"{kind} {name!r}: {err}") from None
