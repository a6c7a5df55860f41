"""TOML files validated from one declaration per file kind (mapping, campaign, search space).

A kind declares its tables once: a :class:`Table` lists its keys, each a
:class:`replay.util.params.Param` (type, default, choices, bounds, doc), a :class:`Value` (what a
``Param`` cannot say: a list of strings, one of several types), a nested :class:`Table` or an
:class:`Each` (named entries ``[channels] gps = {...}``, or an array of tables ``[[dataset]]``), and
which keys are required. :func:`check` walks a parsed document against it and refuses the first
problem in one line, ``TITLE: KEY: unknown key (known: ...)``, ``TITLE: KEY: missing (...)`` or
``TITLE: KEY must be ... (got ...)``, handed to the kind's ``fail(key, text)`` (which names the file,
and the line where it knows it). What a declaration cannot say (a filter's own parameters, a topic's
message type) is checked after it, by the kind's code.
"""

from __future__ import annotations

from dataclasses import dataclass

from replay.util.errors import ReplayError, listed, shown
from replay.util.params import Param  # noqa: F401  (the declarations' other kind of key)


@dataclass(frozen=True)
class Value:
    """A key whose value is one of ``types`` (a list: of ``item`` when given); ``words`` says it."""

    name: str
    types: tuple
    doc: str
    item: type | None = None
    words: str | None = None

    def accepts(self) -> str:
        if self.words:
            return self.words
        words = {str: "a string", list: "a list", dict: "a table", bool: "true or false", float: "a number"}
        text = " or ".join(words.get(t, t.__name__) for t in self.types)
        return text + (f" of {words[self.item][2:]}s" if self.item else "")

    def check(self, value, owner: str = ""):
        ok = isinstance(value, self.types) and not (isinstance(value, bool) and bool not in self.types)
        if ok and self.item is not None and isinstance(value, list):
            ok = all(isinstance(v, self.item) for v in value)
        if not ok:
            where = f"{owner}: " if owner else ""
            raise ReplayError(f"{where}{self.name} must be {self.accepts()} (got {shown(value)})")
        return value


@dataclass(frozen=True)
class Table:
    """A table: its ``keys`` (declarations), the ``required`` ones, and how messages name it.
    ``open``: keys not declared here are checked by the kind's code (a task's parameters).
    ``shorthand``: a string in place of the table means ``{shorthand: string}``; ``expect`` says what a
    value that is not a table should have been."""

    name: str
    title: str
    keys: tuple = ()
    required: tuple = ()
    doc: str = ""
    open: bool = False
    shorthand: str | None = None
    expect: str = "a table"

    def known(self) -> dict:
        return {k.name: k for k in self.keys}


@dataclass(frozen=True)
class Each:
    """A key holding entries of one :class:`Table`: named (``name = {...}``; ``{name}`` in the entry's
    title is the entry's name) or, when ``array``, an array of tables."""

    name: str
    entry: Table
    array: bool = False
    doc: str = ""


def check(table: Table, doc, fail, title: str | None = None) -> None:
    """Refuse (``raise fail(key, text)``) the first key of ``doc`` that ``table`` does not declare, the
    first required key missing, the first value of the wrong type; then the nested tables alike."""
    title = table.title if title is None else title
    head = f"{title}: " if title else ""
    if isinstance(doc, str) and table.shorthand:
        doc = {table.shorthand: doc}
    if not isinstance(doc, dict):
        short = f" (or a {table.shorthand} string)" if table.shorthand else ""
        raise fail(table.name, f"{head}expected {table.expect}{short}")
    known = table.known()
    for key in doc:
        if key not in known and not table.open:
            raise fail(key, f"{head}{listed([str(key)])}: unknown key (known: {', '.join(sorted(known))})")
    for key in table.required:
        if key not in doc:
            raise fail(table.name, f"{head}{key}: missing ({known[key].doc})")
    for key, value in doc.items():
        decl = known.get(key)
        if isinstance(decl, Table):
            check(decl, value, fail)
        elif isinstance(decl, Each):
            check_each(decl, value, fail, head)
        elif decl is not None and not (value is None and getattr(decl, "optional", False)):
            try:
                decl.check(value)
            except ReplayError as e:
                raise fail(key, f"{head}{e}") from None


def check_each(decl: Each, value, fail, head: str = "") -> None:
    """:func:`check` of every entry of ``value`` (a table of named entries, or an array of tables)."""
    if decl.array:
        if not isinstance(value, list):
            raise fail(decl.name, f"{head}{decl.name}: expected [[{decl.name}]] tables")
        for entry in value:
            check(decl.entry, entry, fail)
        return
    if not isinstance(value, dict):
        raise fail(decl.name, f"{head}{decl.name}: expected a table of name = {decl.entry.shorthand or 'table'}")
    for name, entry in value.items():
        check(decl.entry, entry, fail, decl.entry.title.format(name=listed([str(name)])))
