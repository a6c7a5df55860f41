"""The search space of ``replay tune``: one entry per parameter, checked before any trial.

An entry names ``FILTER.PARAM`` (a filter's declared parameter, searched in that
filter's study) or ``task.PARAM`` (a task parameter, searched in every filter's
study: e.g. the Q and R a filter assumes, where the task declares them). Its value:

* ``log[a, b]`` — a float on a log scale, 0 < a < b;
* ``[a, b]`` — a range, integer or float by the parameter's declared type (an integer
  parameter takes integer bounds, a float one bounds written as floats: ``[0.1, 2.0]``);
* ``choice[v1, v2, ...]`` (or, in a TOML file, an array that is not two numbers) — choices.

On the command line ``--param 'ukf.alpha=log[1e-3,1]'``; in a TOML file
``ukf.alpha = "log[1e-3, 1]"``, ``pf.n_particles = [100, 5000]``. Every bound and choice
is checked against the declaration (:class:`replay.util.params.Param`); an unknown filter
or parameter, an empty or inverted range, a log range with a non-positive bound, an
integer range on a float parameter (or the reverse) is one line, :class:`ReplayError`.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

from replay.util import tomlfile, tomlschema
from replay.util.tomlschema import Each, Table
from replay.util.errors import ReplayError, shown
from replay.filters import FILTERS
from replay.tasks import task_class
from replay.util.lookup import resolve

SPACE = Each(  # the one declaration of a search-space file: its entries' values are checked by make_dim
    "space",
    Table("owner", "{name}", open=True, expect="FILTER.PARAM = SPEC (a table of parameters per filter)"),
    doc="FILTER (or task) = { PARAM = SPEC }: log[a, b], [a, b] or choice[...] per parameter",
)
_SPEC = re.compile(r"^\s*(log|choice)?\s*\[(.*)\]\s*$", re.S)


@dataclass(frozen=True)
class Dim:
    """One searched parameter: ``owner`` a filter name or ``task``; ``kind`` log, int, float or choice."""

    owner: str
    name: str
    kind: str
    low: float | int | None = None
    high: float | int | None = None
    choices: tuple = ()

    @property
    def key(self) -> str:
        return f"{self.owner}.{self.name}"

    def text(self) -> str:
        if self.kind == "choice":
            return "choice[" + ", ".join(json.dumps(c) for c in self.choices) + "]"
        return f"{'log' if self.kind == 'log' else ''}[{self.low!r}, {self.high!r}]"

    def distribution(self):
        # lazy: optuna takes ~1 s to import, only when a study is made (replay tune)
        import optuna.distributions as d  # noqa: PLC0415

        if self.kind == "choice":
            return d.CategoricalDistribution(list(self.choices))
        if self.kind == "int":
            return d.IntDistribution(int(self.low), int(self.high))
        return d.FloatDistribution(float(self.low), float(self.high), log=self.kind == "log")


def _value(text: str, where: str):
    text = text.strip()
    try:
        return json.loads(text)
    except ValueError:
        if re.fullmatch(r"[A-Za-z_][\w\-]*", text):
            return text  # a bare word: a string choice
        raise ReplayError(f"{where}: {shown(text)} is not a number or a value") from None


def parse_value(raw, where: str):
    """An entry's value (a string or a TOML value) -> (kind word or None, list of bounds/choices)."""
    if isinstance(raw, list):
        if len(raw) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in raw):
            return None, raw
        return "choice", raw
    if not isinstance(raw, str):
        raise ReplayError(f"{where}: expected log[a,b], [a,b] or choice[...], got {shown(raw)}")
    m = _SPEC.match(raw)
    if not m:
        raise ReplayError(f"{where}: {shown(raw)} is not log[a,b], [a,b] or choice[v1,v2,...]")
    parts = [p for p in m.group(2).split(",")]
    if m.group(2).strip() == "":
        parts = []
    return m.group(1), [_value(p, where) for p in parts]


def make_dim(owner: str, name: str, raw, declarations, where: str) -> Dim:
    """Check one entry against the parameter's declaration."""
    known = {p.name: p for p in declarations}
    if name not in known:
        raise ReplayError(f"{where}: {owner} has no parameter {shown(name)} (known: {', '.join(known) or 'none'})")
    p = known[name]
    word, vals = parse_value(raw, where)
    if word == "choice":
        if not vals:
            raise ReplayError(f"{where}: no choices given")
        for v in vals:
            try:
                p.check(v, owner)
            except ReplayError as e:
                raise ReplayError(f"{where}: {e}") from None
        return Dim(owner, name, "choice", choices=tuple(vals))
    if len(vals) != 2:
        raise ReplayError(f"{where}: a range takes two bounds [a, b] (got {len(vals)})")
    a, b = vals
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
        raise ReplayError(f"{where}: range bounds must be numbers (got {shown(a)}, {shown(b)})")
    if p.type not in (int, float):
        raise ReplayError(f"{where}: {owner}.{name} is {p.accepts()}: give choice[...], not a range")
    if not a < b:
        raise ReplayError(f"{where}: empty or inverted range [{shown(a)}, {shown(b)}] (need low < high)")
    if word == "log" and a <= 0:
        raise ReplayError(f"{where}: a log range needs positive bounds (got low {shown(a)})")
    ints = all(isinstance(v, int) for v in vals)
    if p.type is float and ints and word != "log":
        raise ReplayError(
            f"{where}: integer range [{a}, {b}] on the float parameter {owner}.{name}: "
            f"write the bounds as floats ([{float(a)}, {float(b)}])"
        )
    if p.type is int and not ints:
        raise ReplayError(
            f"{where}: {owner}.{name} is an integer parameter: the range needs integer bounds "
            f"(got [{shown(a)}, {shown(b)}])"
        )
    for v in vals:
        try:
            p.check(v, owner)
        except ReplayError as e:
            raise ReplayError(f"{where}: bound {shown(v)}: {e}") from None
    kind = "log" if word == "log" else ("int" if p.type is int else "float")
    if kind == "log" and p.type is int:
        raise ReplayError(f"{where}: log ranges are for float parameters; {owner}.{name} is an integer: use [a, b]")
    return Dim(owner, name, kind, a, b)


def entries_from_cli(params) -> list[tuple[str, object, str]]:
    """``--param KEY=SPEC`` -> [(key, spec text, where)]."""
    out = []
    for text in params:
        key, eq, spec = text.partition("=")
        if not eq or "." not in key:
            raise ReplayError(
                f"--param {shown(text)}: expected FILTER.PARAM=SPEC or task.PARAM=SPEC, e.g. 'ukf.alpha=log[1e-3,1]'"
            )
        out.append((key.strip(), spec, f"--param {key.strip()}"))
    return out


def entries_from_file(path) -> list[tuple[str, object, str]]:
    """A TOML search-space file -> [(key, value, where)] (``FILE: KEY`` in messages)."""
    path = Path(path)
    doc, _ = tomlfile.load(path, "a search space", f"--space {path}")
    tomlschema.check_each(SPACE, doc, lambda key, text: ReplayError(f"{path}: {text}"))
    out = []
    for owner, table in doc.items():
        for name, value in table.items():
            out.append((f"{owner}.{name}", value, f"{path}: {owner}.{name}"))
    return out


def build(entries, filters, task: str) -> dict[str, list[Dim]]:
    """{filter: [Dim]} for each filter (task entries in each); unknown owners refused."""

    per = {f: [] for f in filters}
    seen = set()
    for key, raw, where in entries:
        owner, _, name = key.partition(".")
        if key in seen:
            raise ReplayError(f"{where}: given twice")
        seen.add(key)
        if owner == "task":
            if getattr(task_class(task), "SYNTHETIC", False):  # its parameters also draw the measurements
                raise ReplayError(
                    f"{where}: task {shown(task)} draws its measurements from the reference with its own "
                    "parameters: searching them would score every trial on other data; search the "
                    "filters' noise settings instead (FILTER.q_scale, FILTER.r_scale, ...)"
                )
            dim = make_dim(f"task {shown(task)}", name, raw, task_class(task).PARAMS, where)
            for f in filters:
                per[f].append(Dim("task", name, dim.kind, dim.low, dim.high, dim.choices))
            continue
        if owner not in FILTERS:
            raise ReplayError(f"{where}: unknown filter {shown(owner)} (known: {', '.join(sorted(FILTERS))})")
        if owner not in per:
            raise ReplayError(f"{where}: filter {shown(owner)} is not among --filters ({', '.join(filters)})")
        dim = make_dim(f"filter {shown(owner)}", name, raw, _declared(owner), where)
        per[owner].append(Dim(owner, name, dim.kind, dim.low, dim.high, dim.choices))
    return per


def _declared(name: str):
    """The declared parameters of filter ``name``."""

    return resolve(FILTERS, name, "filter").PARAMS
