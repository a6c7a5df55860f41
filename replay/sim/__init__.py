"""Simulated datasets: seeded generators of frames, each with declared parameters.

A generator is ``make_frame(rng, **params) -> Frame`` registered by a
``[[dataset]]`` entry (``generator = "module:function"``). Its parameters are
declared once, with :func:`generator`: the declarations give the defaults,
validate every call strictly (unknown names, wrong types and values out of
bounds are refused with one line) and are what ``replay list datasets`` shows;
the function itself receives every parameter, defaults filled in.

:class:`Numbers` and :class:`Intervals` are the two list-valued parameter kinds
the simulators need beyond :class:`replay.util.params.Param`: a list of
numbers bounded element by element, and a list of ``[start, end)`` intervals
(declared with ``type=list``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, make_dataclass, replace

from replay.util.params import Param, _is_number, validate
from replay.frame import Frame, Simulation


def generator(params: tuple[Param, ...], record: bool = False):
    """Decorate ``make_frame(rng, **params)``: validate ``params`` against ``params`` first.

    The decorated function carries the declarations as ``PARAMS``. ``record=True``: the function receives
    the values as one record, ``make_frame(rng, p)`` (a frozen dataclass with one field per declaration,
    in their order), instead of one keyword each; it is still called ``make_frame(rng, **params)``.
    The frame it returns carries that record as ``frame.simulation.params`` (:class:`replay.frame.Simulation`,
    with the step and initial state the function declared there, if any) and the simulator's module as
    ``frame.simulation.generator``.
    """

    def wrap(make_frame):
        owner = f"simulator {make_frame.__module__}"
        kind = make_dataclass("Params", [p.name for p in params], frozen=True)

        @functools.wraps(make_frame)
        def make(rng, **given):
            values = validate(params, given, owner)
            p = kind(**values)
            frame = make_frame(rng, p) if record else make_frame(rng, **values)
            if isinstance(frame, Frame):  # (what else it returns is refused where a frame is needed)
                frame.simulation = replace(frame.simulation or Simulation(), generator=make_frame.__module__, params=p)
            return frame

        make.PARAMS = params
        return make

    return wrap


def _to_list(value):
    return value.tolist() if hasattr(value, "tolist") and not _is_number(value) else value


@dataclass(frozen=True)
class Numbers(Param):
    """A list of numbers (of ``length`` when given), ``low``/``high`` bounding each element."""

    def accepts(self) -> str:
        size = self.length or "one or more"
        each = f", each{self.bounds_text()}" if self.bounds_text() else ""
        return f"a list of {size} finite numbers{each}" + (" (or null)" if self.optional else "")

    def check(self, value, owner: str = ""):
        return super().check(_to_list(value), owner)

    def _coerce(self, v):
        if not isinstance(v, (list, tuple)) or not v or (self.length is not None and len(v) != self.length):
            return False, v
        if not all(_is_number(x) and math.isfinite(x) and self._in_bounds(float(x)) for x in v):
            return False, v
        return True, tuple(float(x) for x in v)


@dataclass(frozen=True)
class Intervals(Param):
    """A list of ``[start, end]`` pairs of finite numbers with start < end."""

    def accepts(self) -> str:
        return "a list of [start, end] pairs of finite numbers with start < end"

    def check(self, value, owner: str = ""):
        return super().check(_to_list(value), owner)

    def _coerce(self, v):
        if not isinstance(v, (list, tuple)):
            return False, v
        out = []
        for pair in v:
            if not (
                isinstance(pair, (list, tuple))
                and len(pair) == 2
                and all(_is_number(x) and math.isfinite(x) for x in pair)
                and pair[0] < pair[1]
            ):
                return False, v
            out.append((float(pair[0]), float(pair[1])))
        return True, tuple(out)
