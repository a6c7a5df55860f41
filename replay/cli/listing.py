"""``replay list filters|tasks|adapters|datasets|reproductions [NAME]``: what is registered, with parameters.

One line per entry (its name and the first sentence of its documentation, as
plain text), then one indented line per parameter from its declaration
(:meth:`replay.util.params.Param.describe`: ``name = default [unit]: what it
accepts. doc``). Adapters declare no parameters: their options are read from
the signature of their ``load`` function.
"""
from __future__ import annotations

import inspect
import re
import sys

import click

KINDS = ("filters", "tasks", "adapters", "datasets", "reproductions")
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


def entries(kind: str) -> list[tuple[str, str, list[str]]]:
    """``(name, one-line doc, parameter lines)`` of every entry of ``kind``."""
    from replay.util.lookup import resolve

    if kind == "datasets":
        return _datasets()
    if kind == "filters":
        from replay.cli.params import filter_declarations
        from replay.filters import FILTERS

        out = []
        for name in sorted(FILTERS):
            cls = resolve(FILTERS, name, "filter")
            out.append((name, summary(cls, name), _declared(filter_declarations(name))))
        return out
    if kind == "tasks":
        from replay.tasks import TASKS, task_class

        return [(n, summary(task_class(n), n), _declared(task_class(n).PARAMS)) for n in sorted(TASKS)]
    if kind == "adapters":
        from replay.adapters import ADAPTERS

        return [(n, summary(f := resolve(ADAPTERS, n, "adapter"), n), _signature(f)) for n in sorted(ADAPTERS)]
    from replay.reproduce import REPRODUCTIONS

    return [(n, summary(sys.modules[resolve(REPRODUCTIONS, n, "reproduction").__module__], n), [])
            for n in sorted(REPRODUCTIONS)]


def _datasets():
    from replay import registry

    out = []
    for ds in registry.all_datasets().values():
        if ds.kind == "sim":
            lines = _declared(registry.generator(ds).PARAMS)
        else:
            lines = [f"{INDENT}(a recording read by the {ds.adapter} adapter: `replay list adapters`)"]
        out.append((ds.id, plain_text(ds.description), lines))
    return out


def render(kind: str, name: str | None = None) -> list[str]:
    """The lines ``replay list KIND [NAME]`` prints."""
    from replay.util.errors import ReplayError

    rows = entries(kind)
    if name is not None:
        rows = [r for r in rows if r[0] == name]
        if not rows:
            known = ", ".join(r[0] for r in entries(kind))
            raise ReplayError(f"replay list {kind}: no {kind[:-1]} {name!r} (known: {known})")
    width = max(len(r[0]) for r in rows) + 2
    lines = []
    for entry, doc, params in rows:
        lines.append(f"{entry:{width}s}{doc}".rstrip())
        lines += params
    return lines


@click.command("list")
@click.argument("what", type=click.Choice(KINDS))
@click.argument("name", required=False)
def list_cmd(what, name):
    """List the registered filters, tasks, adapters, datasets or reproductions, with their parameters.

    NAME shows one of them.
    """
    for line in render(what, name):
        click.echo(line)
