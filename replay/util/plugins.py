"""Plugins: named filters, tasks, adapters and datasets, from replay and from other packages.

A :class:`Registry` maps a name (as on the command line) to ``"module:attribute"``.
Its entries, in this order:

* the **built-ins** (``FILTERS``, ``TASKS``, ``ADAPTERS``), a plain dict;
* names **registered in this session** (:meth:`Registry.register`: a notebook's class);
* the **entry points** of its group (``replay.filters``, ``replay.tasks``,
  ``replay.adapters``) of every installed distribution, read through
  :mod:`importlib.metadata` on first use (no plugin module is imported until its
  entry is used);
* any name of the form ``"package.module:Class"`` resolves too (a quick try
  without packaging: ``--filters my_pkg.filters:MyFilter``).

A bad plugin never breaks the others, and each problem is one line naming the plugin
and its distribution: a name that is not usable on the command line, a target that
is not ``module:attribute``, a name taken by a built-in, two distributions
registering one name (neither is used), an entry point that raises on import, an
object that does not implement the protocol (``check``), invalid parameter
declarations (:func:`declaration_problem`). Discovery problems are listed by
:meth:`Registry.problems` (``replay list`` prints them as warnings); using a broken
entry raises its line as :class:`~replay.util.errors.ReplayError`.
"""

from __future__ import annotations

import importlib.metadata as metadata
import inspect
import re
from collections.abc import MutableMapping
from dataclasses import dataclass
from importlib import import_module

from replay.util.errors import ReplayError
from replay.util.params import Param

NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_+-]*")  # usable in --filters a,b and in -p NAME.param=...
_IDENT = r"[A-Za-z_]\w*"
TARGET = re.compile(rf"{_IDENT}(\.{_IDENT})*:{_IDENT}(\.{_IDENT})*")
GROUPS = {
    "filter": "replay.filters",
    "task": "replay.tasks",
    "adapter": "replay.adapters",
    "dataset": "replay.datasets",
}


@dataclass(frozen=True)
class Plugin:
    """One entry point: its name, ``module:attribute`` and the distribution that declares it."""

    name: str
    target: str
    dist: str = ""  # "name version", or "" when unknown

    @property
    def where(self) -> str:
        """'entry point of replay-plugin-example 0.1.0, pkg.mod:Class' (for messages)."""
        return f"entry point of {self.dist or 'an unknown distribution'}, {self.target}"


def _dist(ep) -> str:
    dist = getattr(ep, "dist", None)
    if dist is None:
        return ""
    try:
        return f"{dist.metadata['Name'] or dist.name} {dist.version}"
    except Exception:  # noqa: BLE001 — broken metadata: name it as far as known
        return str(getattr(dist, "name", "") or "")


def one_line(err: BaseException) -> str:
    """``Type: first line of the message``."""
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0]}" if text else type(err).__name__


def discover(group: str, kind: str, valid=NAME.fullmatch) -> tuple[dict, dict, list]:
    """Entry points of ``group``: ``({name: Plugin}, {name: conflict line}, [problem lines])``.

    Nothing is imported. Two distributions (or two targets) under one name are a conflict:
    neither is used, and using the name raises the conflict's line.
    """
    try:
        eps = metadata.entry_points(group=group)
    except Exception as err:  # noqa: BLE001 — one distribution's broken metadata must not stop replay
        return {}, {}, [f"{group}: the installed entry points cannot be read ({one_line(err)})"]
    found: dict[str, list[Plugin]] = {}
    problems = []
    for ep in eps:
        p = Plugin(ep.name, str(ep.value).strip(), _dist(ep))
        if not valid(p.name):
            problems.append(f"{kind} {p.name!r} ({p.where}): not a usable {kind} name; ignored")
        elif not TARGET.fullmatch(p.target):
            problems.append(f"{kind} {p.name!r} ({p.where}): the target must be 'module:attribute'; ignored")
        elif p not in found.setdefault(p.name, []):
            found[p.name].append(p)
    plugins, conflicts = {}, {}
    for name, ps in found.items():
        if len(ps) == 1:
            plugins[name] = ps[0]
            continue
        line = (
            f"{kind} {name!r} is registered twice ({'; '.join(sorted(p.where for p in ps))}): "
            "neither is used; uninstall one"
        )
        conflicts[name] = line
        problems.append(line)
    return plugins, conflicts, problems


def refuse_unallowed(name, allowed, where: str, kind: str, reader: str) -> None:
    """The one rule for names read from a file (a manifest, a campaign file, a ``tuned.toml``): a
    ``package.module:Class`` name is refused, before anything is imported, unless its module is in
    ``allowed`` (``--allow-module``); built-in, installed (entry-point) and this session's names have
    no ``:`` and pass. One line: ``where``, the name, the module, what ``reader`` loads, the flag."""
    if isinstance(name, str) and TARGET.fullmatch(name):
        module = name.partition(":")[0]
        if module not in ({allowed} if isinstance(allowed, str) else set(allowed or ())):
            raise ReplayError(
                f"{where}: {name!r:.120} would import the module {module}: {reader} loads only built-in "
                f"and installed (entry-point) {kind}s; if you trust that module, pass --allow-module {module}"
            )


def load_target(target: str):
    """The object ``"module:attribute"`` names (the attribute may be dotted)."""
    module, _, attr = target.partition(":")
    obj = import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


class Registry(MutableMapping):
    """Name -> ``"module:attribute"`` of one kind (module docstring).

    ``builtin`` is the dict of built-in entries (kept as given: assigning to the registry
    changes it). ``check(obj) -> str | None`` tells what is wrong with a loaded plugin.
    """

    def __init__(self, kind: str, builtin: dict, check=None, group: str | None = None):
        self.kind, self.builtin, self._check = kind, builtin, check
        self.group = group or GROUPS[kind]
        self._session: dict = {}  # name -> (target, object)
        self.refresh()

    def refresh(self) -> None:
        """Forget what was discovered and loaded (after installing or removing a plugin)."""
        self._plugins = None
        self._conflicts: dict = {}
        self._problems: list = []
        self._loaded: dict = {}
        self._failed: dict = {}

    def _discovered(self) -> dict:
        if self._plugins is None:
            plugins, self._conflicts, problems = discover(self.group, self.kind)
            for name in [n for n in plugins if n in self.builtin]:
                problems.append(
                    f"{self.kind} {name!r} ({plugins.pop(name).where}): the name is taken by "
                    f"the built-in {self.kind}; ignored"
                )
            self._plugins, self._problems = plugins, problems
        return self._plugins

    # --- the mapping ------------------------------------------------------------------
    def __getitem__(self, name):
        if name in self.builtin:
            return self.builtin[name]
        if name in self._session:
            return self._session[name][0]
        plugins = self._discovered()
        if name in plugins:
            return plugins[name].target
        if isinstance(name, str) and (name in self._conflicts or TARGET.fullmatch(name)):
            return name
        raise KeyError(name)

    def __iter__(self):
        plugins = self._discovered()
        yield from self.builtin
        yield from (n for n in self._session if n not in self.builtin)
        yield from sorted(n for n in plugins if n not in self.builtin and n not in self._session)

    def __len__(self):
        return sum(1 for _ in self)

    def __setitem__(self, name, target):
        self.builtin[name] = target
        self._loaded.pop(name, None)

    def __delitem__(self, name):
        del self.builtin[name]
        self._loaded.pop(name, None)

    def __repr__(self):
        return f"<{self.kind} registry: {', '.join(self)}>"

    # --- origins and problems -----------------------------------------------------------
    def origin(self, name: str) -> str:
        """Where an entry comes from: 'built-in', 'this session', the distribution, or the module."""
        if name in self.builtin:
            return "built-in"
        if name in self._session:
            return "registered in this session"
        plugin = self._discovered().get(name)
        if plugin is not None:
            return plugin.dist or "an unknown distribution"
        return f"module {name.partition(':')[0]}"

    def is_plugin(self, name: str) -> bool:
        """True for an entry point of another distribution."""
        return name not in self.builtin and name not in self._session and name in self._discovered()

    def problems(self) -> list[str]:
        """One line per plugin that cannot be used (discovery, and loads tried so far)."""
        self._discovered()
        return self._problems + [m for m in self._failed.values() if m not in self._problems]

    # --- using an entry --------------------------------------------------------------------
    def register(self, name: str, obj) -> str:
        """Register ``obj`` (a class or function of this session) as ``name``; returns the name."""
        if not isinstance(name, str) or not NAME.fullmatch(name):
            raise ReplayError(
                f"{self.kind} name {name!r}: use letters, digits, '-', '_' or '+' "
                "(it is written in --filters a,b and -p NAME.param=...)"
            )
        if name in self.builtin or name in self._discovered():
            raise ReplayError(
                f"{self.kind} name {name!r} is taken by the {self.origin(name)} {self.kind}; choose another"
            )
        problem = self._check(obj) if self._check else None
        if problem:
            raise ReplayError(f"{self.kind} {name!r} (registered in this session): {problem}")
        target = f"{getattr(obj, '__module__', '?')}:{getattr(obj, '__qualname__', name)}"
        self._session[name] = (target, obj)
        self._loaded[name] = obj
        return name

    def unregister(self, name: str) -> None:
        """Forget a name registered in this session (nothing else can be unregistered)."""
        if name not in self._session:
            raise ReplayError(f"{self.kind} {name!r} was not registered in this session")
        del self._session[name]
        self._loaded.pop(name, None)

    def load(self, name: str):
        """The object registered as ``name``, checked; a one-line ReplayError otherwise."""
        if name in self.builtin:  # trusted: imported as is, every time (as a module attribute)
            return load_target(self.builtin[name])
        if name in self._loaded:
            return self._loaded[name]
        if name in self._failed:
            raise ReplayError(self._failed[name])
        if name in self._session:
            return self._session[name][1]
        plugins = self._discovered()
        if isinstance(name, str) and name in self._conflicts:
            raise ReplayError(self._conflicts[name])
        if name in plugins:
            label = f"{self.kind} {name!r} ({plugins[name].where})"
        elif isinstance(name, str) and TARGET.fullmatch(name):
            label = f"{self.kind} {name!r}"
        else:
            hint = " or a 'module:Class' name" if self.kind in ("filter", "task") else ""
            raise ReplayError(f"unknown {self.kind} {name!r} (known: {', '.join(sorted(self))}{hint})")
        try:
            obj = load_target(self[name])
        except (Exception, SystemExit) as err:  # noqa: BLE001 — any failure of a plugin is its own
            return self._fail(name, f"{label}: cannot be imported: {one_line(err)}")
        problem = self._check(obj) if self._check else None
        if problem:
            return self._fail(name, f"{label}: {problem}")
        self._loaded[name] = obj
        return obj

    def _fail(self, name, line):
        self._failed[name] = line
        raise ReplayError(line)


# ------------------------------------------------------------------ what a plugin must be


def describe(obj) -> str:
    """'a function', 'the module x', 'an int', 'the class X' (for messages)."""
    if inspect.isclass(obj):
        return f"the class {obj.__qualname__}"
    if inspect.ismodule(obj):
        return f"the module {obj.__name__}"
    if inspect.isroutine(obj):
        return f"the function {getattr(obj, '__qualname__', obj)}"
    return f"{type(obj).__name__} {obj!r:.40}"


def declaration_problem(params) -> str | None:
    """What is wrong with a ``PARAMS`` declaration (:mod:`replay.util.params`), or None."""
    if not isinstance(params, (tuple, list)):
        return f"PARAMS must be a tuple of replay.util.params.Param (got {type(params).__name__})"
    seen = set()
    for p in params:
        if not isinstance(p, Param):
            return f"PARAMS holds {describe(p)}, not a replay.util.params.Param"
        if not isinstance(p.name, str) or not p.name.isidentifier():
            return f"parameter name {p.name!r} is not an identifier"
        if p.name in seen:
            return f"parameter {p.name!r} is declared twice"
        seen.add(p.name)
        if p.low is not None and p.high is not None and p.low > p.high:
            return f"parameter {p.name!r}: low {p.low} is above high {p.high}"
        try:
            p.check(p.default)
        except ReplayError as err:
            return f"parameter {p.name!r}: its default is refused by its own declaration ({err})"
        except Exception as err:  # noqa: BLE001 — a declaration that cannot even check its default
            return f"parameter {p.name!r}: its declaration cannot check its default ({one_line(err)})"
    return None


def class_problem(obj, base: type, base_name: str, needs) -> str | None:
    """A plugin class: a subclass of ``base`` overriding one of ``needs`` (alternatives, each a
    tuple of method names), with valid declarations and a keyword-only constructor."""
    if not (inspect.isclass(obj) and issubclass(obj, base)):
        return f"is {describe(obj)}, not a subclass of {base_name}"
    if not any(all(getattr(obj, m) is not getattr(base, m) for m in alt) for alt in needs):
        return "does not implement " + " or ".join("/".join(f"{m}()" for m in alt) for alt in needs)
    problem = declaration_problem(getattr(obj, "PARAMS", ()))
    if problem:
        return problem
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return None
    positional = [
        p.name
        for p in sig.parameters.values()
        if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD, p.VAR_POSITIONAL)
    ]
    if positional:
        return f"its constructor takes positional parameters ({', '.join(positional)}): parameters are keyword-only"
    return None
