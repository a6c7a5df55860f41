"""Declared parameters: each filter, task and simulated dataset states its parameters once.

A :class:`Param` names a parameter, its type, default, bounds, unit and a
one-line doc (in the spirit of Stone Soup's ``Property``). The declarations
drive everything that touches parameters: strict validation (:func:`validate`),
``replay list``, the ``--help`` texts, the manifest and campaign-file checking.

Validation is strict, with one line naming the owner, the parameter, what it
accepts and the value given:

* ``int`` accepts integers only (not ``1.5``, not ``true``, not ``"3"``);
* ``float`` accepts integers and floats, finite unless ``finite=False``
  (never ``true``);
* ``bool`` accepts ``true``/``false`` only;
* ``str`` accepts strings, one of ``choices`` when given;
* ``list`` accepts a list (or tuple) of numbers, of ``length`` when given;
* ``dict`` accepts a mapping with string keys; ``os.PathLike`` a non-empty path (a string or a path);
* ``low``/``high`` bound numbers (inclusive unless ``low_open``/``high_open``);
* ``optional=True`` also accepts ``None``.

Classes declare ``PARAMS`` (a tuple of :class:`Param`) and inherit from
:class:`Declared`, whose keyword-only constructor validates and sets them.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from typing import Any

from replay.util.errors import SHOWN, ReplayError, shown
import numpy as np

TYPES = (int, float, bool, str, list, dict, os.PathLike)


@dataclass(frozen=True)
class Param:
    """One declared parameter (see the module docstring)."""

    name: str
    type: type
    default: Any
    doc: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple | None = None
    optional: bool = False
    finite: bool = True
    length: int | None = None

    def __post_init__(self):
        if self.type not in TYPES:
            raise TypeError(f"Param {self.name}: type must be one of {TYPES}")

    # --- what it accepts, in words ----------------------------------------------------
    def accepts(self) -> str:
        """What the parameter accepts, e.g. 'an integer >= 1' or 'one of systematic, multinomial'."""
        if self.type is bool:
            text = "true or false"
        elif self.type is str:
            text = ("one of " + ", ".join(map(str, self.choices))) if self.choices else "a string"
        elif self.type is list:
            text = "a list of numbers" + (f" of length {self.length}" if self.length else "")
        elif self.type is dict:
            text = "an object (a dict with string keys)"
        elif self.type is os.PathLike:
            text = "a path (a non-empty string or a pathlib.Path)"
        else:
            text = "an integer" if self.type is int else "a finite number" if self.finite else "a number"
            text += self.bounds_text()
        return text + (" (or null)" if self.optional else "")

    def bounds_text(self) -> str:
        lo, hi = _bound(self.low), _bound(self.high)
        if self.low is not None and self.high is not None:
            return f" in {'(' if self.low_open else '['}{lo}, {hi}{')' if self.high_open else ']'}"
        if self.low is not None:
            return f" {'>' if self.low_open else '>='} {lo}"
        if self.high is not None:
            return f" {'<' if self.high_open else '<='} {hi}"
        return ""

    def describe(self) -> str:
        """One line for ``replay list`` and ``--help``: name, default, what it accepts, unit, doc."""
        unit = f" [{self.unit}]" if self.unit else ""
        return f"{self.name} = {_show(self.default)}{unit}: {self.accepts()}. {self.doc}"

    # --- checking ------------------------------------------------------------------------
    def check(self, value, owner: str = ""):
        """The value, normalised (ints as float for float parameters, lists as tuples), or ReplayError."""
        if value is None and self.optional:
            return None
        ok, out = self._coerce(value)
        if not ok:
            where = f"{owner}: " if owner else ""
            raise ReplayError(f"{where}{self.name} must be {self.accepts()} (got {_show(value)})")
        return out

    def _coerce(self, v):
        if self.type is bool:
            return isinstance(v, bool), v
        if self.type is str:
            return isinstance(v, str) and (self.choices is None or v in self.choices), v
        if self.type is dict:
            return isinstance(v, dict) and all(isinstance(k, str) for k in v), v
        if self.type is os.PathLike:
            return isinstance(v, (str, os.PathLike)) and str(os.fspath(v)).strip() != "" and "\0" not in str(
                os.fspath(v)
            ), v
        if self.type is list:
            if not isinstance(v, (list, tuple)) or (self.length is not None and len(v) != self.length):
                return False, v
            if not all(_is_number(x) and (not self.finite or math.isfinite(x)) for x in v):
                return False, v
            return True, tuple(float(x) for x in v)
        if self.type is int:
            if not (_is_integer(v)):
                return False, v
            v = int(v)
        else:
            if not _is_number(v):
                return False, v
            v = float(v)
            if math.isnan(v) or (self.finite and not math.isfinite(v)):
                return False, v
        return self._in_bounds(v), v

    def _in_bounds(self, v) -> bool:
        if self.low is not None and (v < self.low or (self.low_open and v == self.low)):
            return False
        if self.high is not None and (v > self.high or (self.high_open and v == self.high)):
            return False
        return True


def _bound(x) -> str:
    """A bound in words: an integer exactly (2**63 - 1 in full), a float as ``:g``."""
    return "" if x is None else str(x) if isinstance(x, int) else f"{x:g}"


def _is_number(v) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, np.bool_):
        return False
    return isinstance(v, (int, float, np.integer, np.floating))


def _is_integer(v) -> bool:
    """A Python or numpy integer (not a bool, not a float even if integral)."""
    if isinstance(v, bool):
        return False
    if isinstance(v, int):
        return True

    return isinstance(v, np.integer)


def _show(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if v is None:
        return "null"
    if isinstance(v, str):
        return shown(v)
    if isinstance(v, tuple):
        text = "[" + ", ".join(_show(x) for x in v) + "]"
        return text if len(text) <= 2 * SHOWN else f"{text[: 2 * SHOWN]}... ({len(v)} items)"
    text = str(v)
    return text if len(text) <= SHOWN else f"{text[:SHOWN]}... ({len(text)} characters)"


def validate(params: tuple[Param, ...], given: dict, owner: str) -> dict:
    """Every declared parameter's value: ``given`` checked, the rest defaulted.

    An unknown name raises one line naming the owner and the known names.
    """
    known = {p.name: p for p in params}
    for name in given:
        if name not in known:
            raise ReplayError(f"{owner}: unknown parameter {name!r} (known: {', '.join(known) or 'none'})")
    return {p.name: p.check(given[p.name], owner) if p.name in given else p.default for p in params}


def override(params: tuple[Param, ...], name: str, **changes) -> tuple[Param, ...]:
    """``params`` with the declaration of ``name`` changed (e.g. another default in a subclass)."""
    if name not in {p.name for p in params}:
        raise KeyError(name)
    return tuple(replace(p, **changes) if p.name == name else p for p in params)


def without(params: tuple[Param, ...], *names: str) -> tuple[Param, ...]:
    """``params`` less the named ones (a subclass that fixes them)."""
    return tuple(p for p in params if p.name not in names)


class Declared:
    """Keyword-only construction from the class's ``PARAMS``; ``params()`` returns them all.

    ``KIND`` and ``name`` make the owner of an error message ("filter 'pf'").
    Subclasses check relations between parameters in :meth:`check`.
    """

    PARAMS: tuple[Param, ...] = ()
    KIND = "component"
    name = "component"

    def __init__(self, **params):
        for key, value in validate(self.PARAMS, params, self.owner()).items():
            setattr(self, key, value)
        self.check()

    @classmethod
    def owner(cls) -> str:
        return f"{cls.KIND} {cls.name!r}"

    def check(self) -> None:
        """Relations between parameters; raise ReplayError (one line) when violated."""

    def params(self) -> dict:
        """Every declared parameter and its value (lists as lists), for manifests and leaderboards."""
        return {p.name: (list(v) if isinstance(v := getattr(self, p.name), tuple) else v) for p in self.PARAMS}
