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
    """``resolve(...)(**params)``; a wrong parameter name, or any failure of a (plugin's)
    constructor, ``sys.exit`` included -> one-line ReplayError naming it."""
    cls = resolve(table, name, kind)
    try:
        return cls(**params)
    except (ReplayError, KeyboardInterrupt):
        raise
    except TypeError as err:
        raise ReplayError(f"{kind} {name!r}: {err}") from None
    except BaseException as err:  # noqa: BLE001 — a plugin's constructor: its error, in one line
        raise ReplayError(
            f"{kind} {name!r}: its constructor failed: "
            + (f"{type(err).__name__}: {err}".splitlines() or [""])[0][:300]
        ) from err


def params_of(obj, kind: str, name: str) -> dict:
    """``obj.params()`` (a plugin's); its failure -> one-line ReplayError naming it."""
    try:
        return obj.params()
    except (ReplayError, KeyboardInterrupt):
        raise
    except BaseException as err:  # noqa: BLE001 — a plugin's params(): its error, in one line
        raise ReplayError(
            f"{kind} {name!r}: params() failed: " + (f"{type(err).__name__}: {err}".splitlines() or [""])[0][:300]
        ) from err
