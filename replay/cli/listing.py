"""``replay list filters|tasks|adapters|datasets|reproductions|plugins [NAME]``: what is registered.

One line per entry (its name and the first sentence of its documentation, as
plain text), then one indented line per parameter from its declaration
(:meth:`replay.util.params.Param.describe`: ``name = default [unit]: what it
accepts. doc``). Adapters declare their options the same way
(:mod:`replay.adapters.options`); a plugin adapter that declares none shows the
keyword options of its ``load`` function.

Entries of other distributions (entry points, :mod:`replay.util.plugins`) end their
line with their origin, ``(plugin: <distribution> <version>)``; a plugin that cannot be
used is left out and named in one warning line on stderr (the others are listed).
``replay list filters pkg.module:Class`` shows a filter that is not registered.
``replay list plugins`` lists every plugin of the four groups and every problem.
"""

from __future__ import annotations

import inspect
import re
import sys

import click

KINDS = ("filters", "tasks", "adapters", "datasets", "reproductions", "plugins")
INDENT = "    "


def plain_text(text: str) -> str:
    """reST markup made plain: ``x`` -> x, :mod:`a.b` -> a.b, :class:`~a.B` -> B, *x* -> x."""
    text = re.sub(r":[a-z]+:`~?([^`<]*?)\s*<[^`>]*>`", r"\1", text)
    text = re.sub(r":[a-z]+:`~([^`]*)`", lambda m: m.group(1).rsplit(".", 1)[-1], text)
    text = re.sub(r":[a-z]+:`([^`]*)`", r"\1", text)
    text = re.sub(r"``([^`]*)``", r"\1", text)
    text = re.sub(r"`([^`]*)`_?", r"\1", text)
    text = re.sub(r"\*\*([^*]+)\*\*", r"\1", text)
    return re.sub(r"(?<![\w*])\*(\S[^*]*?)\*(?![\w*])", r"\1", text)


def summary(obj, name: str = "") -> str:
    """The first sentence of ``obj``'s documentation (else its module's), as plain text."""
    doc = inspect.getdoc(obj) if getattr(obj, "__doc__", None) else None
    if not doc and getattr(obj, "__module__", None) in sys.modules:
        doc = inspect.getdoc(sys.modules[obj.__module__])
    para = " ".join((doc or "").strip().split("\n\n")[0].split())
    text = plain_text(para)
    if name:  # "``sonar``: an AUV ..." or "replay reproduce 002: ..." -> "an AUV ..."
        text = re.sub(rf"^(replay \w+ )?{re.escape(name)}: ", "", text)
    if len(text) > 160 and ". " in text:
        text = text[: text.index(". ") + 1]
    return text


def _declared(params) -> list[str]:
    return [INDENT + plain_text(p.describe()) for p in params]


def _signature(func, skip=("path",)) -> list[str]:
    sig = inspect.signature(func)
    lines = []
    for p in sig.parameters.values():
        if p.name in skip or p.kind in (p.VAR_POSITIONAL,):
            continue
        if p.kind == p.VAR_KEYWORD:
            lines.append(f"{INDENT}**{p.name}: further options (see the documentation)")
        elif p.default is not inspect.Parameter.empty:
            lines.append(f"{INDENT}{p.name} = {p.default!r}")
    return lines


def entries(kind: str, problems: list | None = None, extra: str | None = None) -> list[tuple[str, str, list[str]]]:
    """``(name, one-line doc, parameter lines)`` of every entry of ``kind``. Plugins that cannot
    be used are left out and their one-line problems appended to ``problems``; ``extra``: a
    ``module:Class`` name to show too."""
    from replay.util.errors import ReplayError
    from replay.util.lookup import resolve

    problems = [] if problems is None else problems
    if kind == "datasets":
        return _datasets(problems)
    if kind == "plugins":
        return _plugins(problems)
    if kind == "reproductions":
        from replay.reproduce import REPRODUCTIONS

        return [
            (n, summary(sys.modules[resolve(REPRODUCTIONS, n, "reproduction").__module__], n), [])
            for n in sorted(REPRODUCTIONS)
        ]
    table, describe = _table(kind)
    names = sorted(table) + ([extra] if extra and extra not in set(table) and extra in table else [])
    out = []
    for name in names:
        try:
            obj = resolve(table, name, kind[:-1])
            doc, params = summary(obj, name), describe(obj)
        except ReplayError as err:
            if name in table.builtin:
                raise
            problems.append(str(err))
            continue
        if name not in table.builtin:
            origin = f"plugin: {table.origin(name)}" if table.is_plugin(name) else table.origin(name)
            doc = f"{doc} ({origin})".lstrip()
        out.append((name, doc, params))
    problems += [p for p in table.problems() if p not in problems]
    return out


def _table(kind):
    """The registry of ``kind`` and how to list an entry's parameters."""
    if kind == "filters":
        from replay.filters import FILTERS

        return FILTERS, lambda cls: _declared(cls.PARAMS)
    if kind == "tasks":
        from replay.tasks import TASKS

        return TASKS, lambda cls: _declared(cls.PARAMS)
    from replay.data.plugins import ADAPTERS

    return ADAPTERS, lambda load: _declared(load.PARAMS) if hasattr(load, "PARAMS") else _signature(load)


def _datasets(problems):
    from replay.data import registry
    from replay.data.faults import HELP as FAULT_HELP
    from replay.data.views import VIEW_PARAMS

    out = []
    for ds in registry.all_datasets().values():
        if ds.kind == "sim":
            lines = _declared(registry.generator(ds).PARAMS)
        else:
            lines = [f"{INDENT}(a recording read by the {ds.adapter} adapter: `replay list adapters`)"]
        lines += [line + " (a view: every dataset)" for line in _declared(VIEW_PARAMS)]
        lines.append(f"{INDENT}fault = null: injected sensor faults, {FAULT_HELP} (every dataset; docs/robustness.md)")
        doc = plain_text(ds.description)
        if ds.manifest.startswith("entry point of "):
            doc += f" (plugin: {ds.manifest[len('entry point of ') :].split(', ')[0]})"
        out.append((ds.id, doc, lines))
    problems += registry.plugin_problems()
    return out


def _plugins(problems):
    from replay.api import plugin_rows

    out = []
    for row in plugin_rows():
        if row["problem"]:
            problems.append(row["problem"])
        else:
            out.append((row["name"], f"{row['kind']} from {row['origin']} ({row['target']})", []))
    return out


def render(kind: str, name: str | None = None, problems: list | None = None) -> list[str]:
    """The lines ``replay list KIND [NAME]`` prints; the plugins' problems are appended to ``problems``."""
    from replay.util.errors import ReplayError

    problems = [] if problems is None else problems
    rows = entries(kind, problems, extra=name if name and ":" in name and kind in ("filters", "tasks") else None)
    if name is not None and kind == "adapters" and name not in {r[0] for r in rows}:
        name = _adapter_of(name) or name
    if name is not None:
        rows = [r for r in rows if r[0] == name]
        if not rows:
            known = ", ".join(r[0] for r in entries(kind))
            mine = next((p for p in problems if repr(name) in p), None)  # a broken plugin of that name
            if mine:
                problems.remove(mine)
            raise ReplayError(mine or f"replay list {kind}: no {kind[:-1]} {name!r} (known: {known or 'none'})")
    if not rows:
        return ["(no plugin installed)"] if kind == "plugins" else []
    width = max(len(r[0]) for r in rows) + 2
    lines = []
    for entry, doc, params in rows:
        lines.append(f"{entry:{width}s}{doc}".rstrip())
        lines += params
    return lines


def _adapter_of(family: str) -> str | None:
    """The one adapter that reads the datasets ``family/...`` (``bohai`` -> bohai-csv), else None."""
    from replay.data import registry

    found = {
        ds.adapter
        for ds in registry.all_datasets().values()
        if ds.kind == "file" and (ds.id == family or ds.id.startswith(family.rstrip("/") + "/"))
    }
    return found.pop() if len(found) == 1 else None


@click.command("list")
@click.argument("what", type=click.Choice(KINDS))
@click.argument("name", required=False)
def list_cmd(what, name):
    """List the registered filters, tasks, adapters, datasets, reproductions or plugins, with their parameters.

    NAME shows one of them (for filters and tasks also a module:Class name; for adapters also a
    dataset family, e.g. bohai: the adapter of its datasets). Entries of other
    installed distributions show their origin; a plugin that cannot be used is named in one
    warning line on stderr, and the others are listed.
    """
    problems: list = []
    try:
        lines = render(what, name, problems)
    finally:
        for line in dict.fromkeys(problems):
            click.echo(f"replay: warning: {line}", err=True)
    for line in lines:
        click.echo(line)
