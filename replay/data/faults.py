"""Injected sensor faults: a dataset view that perturbs one sensor channel, declared once.

A fault is the dataset parameter ``fault`` (beside the views ``rate``, ``window``, ``segment`` of
:mod:`replay.data.views`): one specification or a list of them, each ``CHANNEL:KIND:NAME=VALUE,...``
(``gps:outage:t0=120,d=60``) or a table ``{channel = "gps", kind = "outage", t0 = 120, d = 60}``.
So a fault enters the configuration hash, the manifest, ``replay rerun``, campaign units, ``replay
tune`` and the Python API as any dataset parameter does; ``replay eval --fault SPEC`` (repeatable)
and a campaign's ``[[fault]]`` tables are shorthand for it. Checked strictly before any data is
read (:func:`check`: every kind's parameters are :class:`~replay.util.params.Param` declarations,
:data:`KINDS`), stored canonical: ``CHANNEL:KIND:`` then every parameter in declaration order,
defaults filled in.

Applied (:mod:`replay.data.fault_apply`) to the sensor channel of the frame the task receives
(after the views and ``first``), never to the reference; randomness from the run's fault stream
(:data:`replay.util.seeds.FAULT`, one child stream per fault), so every Monte Carlo run on a
recording gets its own draw and a rerun the same bits. Times (``t0``) are seconds from the
frame's first sample. Kinds:

* ``dropout p``: each valid sample lost with probability p (a uniform draw per sample below p:
  the samples lost at p are among those lost at any larger p);
* ``outage t0 d [every]``: silent for ``t0 <= t < t0 + d`` (again every ``every`` seconds);
* ``outliers p s|jump [df]``: a share p of the valid samples (drawn as for dropout) get an error,
  Student-t of ``df`` degrees of freedom and scale ``s`` per component, or of norm ``jump`` in a
  random direction;
* ``bias b [t0]``: ``b`` added from ``t0`` on (one value for every component, or one per component);
* ``drift s [t0]``: a random-walk bias from ``t0``, ``s`` per square-root second per component;
* ``scale k``: the values times ``k``; ``quantize step``: the values rounded to a multiple of ``step``;
* ``delay d``, ``jitter s``, ``clock_offset c [skew]``: the samples' stamps moved (by ``d``; by a
  normal draw of deviation ``s``; by ``c + skew·1e-6·t``), the values unchanged: each sample moves to
  the frame's stamp nearest its new time (the report gives the largest difference); one past either
  end of the frame, or landing where an earlier moved sample landed, is lost;
* ``rate f``: the channel decimated to ``f`` Hz (per grid point the valid sample nearest it within
  half a period, as the ``rate`` view; the kept samples keep their stamps).

Faults that move or remove samples (dropout, outage, delay, jitter, clock_offset, rate) act on the
whole message: the channel and its companions (the channels named ``CHANNEL_...`` valid at exactly
the same samples: a fix's ``gps_sigma``, an odometry's ``odom_velocity``); the others alter the
channel's values only. Each fault adds report lines (``dropped``, ``altered``, ``shifted``) and an
entry of ``meta["faults"]``. Refused in one line: an unknown kind or parameter, a value out of its
bounds, a channel the frame does not have (or a reference channel), a bias of the wrong width, a
value that overflows the channel, a ``rate`` grid of more than 10 points per sample and a fault
that leaves the channel no valid sample.
"""

from __future__ import annotations

import json
import re

from replay.util.errors import ReplayError, shown
from replay.util.params import Param

NAME = "fault"
P = Param("p", float, None, "share of the channel's valid samples", low=0.0, high=1.0)
T0 = Param("t0", float, 0.0, "start, seconds from the frame's first sample", unit="s", low=0.0)
KINDS: dict[str, tuple[Param, ...]] = {
    "dropout": (P,),
    "outage": (
        Param("t0", float, None, "start, seconds from the frame's first sample", unit="s", low=0.0),
        Param("d", float, None, "length (0: none)", unit="s", low=0.0),
        Param("every", float, None, "repeated every so many seconds", unit="s", low=0.0, low_open=True, optional=True),
    ),
    "outliers": (
        P,
        Param("s", float, None, "scale of the Student-t error", low=0.0, low_open=True, optional=True),
        Param("jump", float, None, "norm of a fixed jump in a random direction", low=0.0, low_open=True, optional=True),
        Param(
            "df",
            float,
            None,
            "degrees of freedom of the Student-t error (3 with s)",
            low=0.0,
            low_open=True,
            optional=True,
        ),
    ),
    "bias": (
        Param("b", list, None, "added: one value for every component or one per component"),
        T0,
    ),
    "drift": (Param("s", float, None, "random-walk intensity, per square-root second", low=0.0, low_open=True), T0),
    "scale": (Param("k", float, None, "factor", low=0.0, low_open=True),),
    "delay": (Param("d", float, None, "stamps late by", unit="s", low=0.0, low_open=True),),
    "jitter": (Param("s", float, None, "standard deviation of each stamp's error", unit="s", low=0.0, low_open=True),),
    "clock_offset": (
        Param("c", float, None, "offset of the channel's clock", unit="s"),
        Param("skew", float, 0.0, "clock rate error", unit="ppm", low=-1e5, high=1e5),
    ),
    "rate": (Param("f", float, None, "decimated to this rate", unit="Hz", low=0.0, low_open=True),),
    "quantize": (Param("step", float, None, "rounded to a multiple of", low=0.0, low_open=True),),
}
MOVES = ("dropout", "outage", "delay", "jitter", "clock_offset", "rate")  # act on the whole message
RANDOM = ("dropout", "outliers", "drift", "jitter")
HELP = "CHANNEL:KIND:NAME=VALUE,... (e.g. gps:outage:t0=120,d=60); kinds: " + ", ".join(KINDS)
_CHANNEL = re.compile(r"^[A-Za-z0-9_./-]+$")


def describe() -> list[str]:
    """One line per kind: its parameters (``replay list datasets``, docs)."""
    return [f"{kind}: " + "; ".join(p.describe() for p in params) for kind, params in KINDS.items()]


def check(value, owner: str = "") -> list[str]:
    """``fault`` (one specification or a list) checked and canonical: a list of strings."""
    items = value if isinstance(value, (list, tuple)) else [value]
    if not items:
        raise ReplayError(f"{_where(owner)}fault: an empty list; give a fault ({HELP}) or none")
    return [canonical(*parse(item, owner)) for item in items]


def parse(item, owner: str = "") -> tuple[str, str, dict]:
    """(channel, kind, every parameter checked, defaults filled in) of one specification."""
    where = _where(owner)
    if isinstance(item, str):
        channel, kind, given = _split(item, where)
    elif isinstance(item, dict):
        given = dict(item)
        channel, kind = given.pop("channel", None), given.pop("kind", None)
        if not isinstance(channel, str) or not isinstance(kind, str):
            raise ReplayError(f"{where}fault {_show(item)}: a table needs channel and kind (strings) ({HELP})")
    else:
        raise ReplayError(f"{where}fault must be {HELP}, or a table with channel and kind (got {_show(item)})")
    if not _CHANNEL.match(channel):
        raise ReplayError(f"{where}fault {_show(item)}: {shown(channel)} is not a channel name")
    if kind not in KINDS:
        raise ReplayError(f"{where}fault {_show(item)}: unknown kind {shown(kind)} (known: {', '.join(KINDS)})")
    decl = KINDS[kind]
    owner = f"{where}fault {channel}:{kind}"
    known = {p.name for p in decl}
    for name in given:
        if name not in known:
            raise ReplayError(f"{owner}: unknown parameter {shown(name)} (known: {', '.join(known)})")
    if kind == "bias" and isinstance(given.get("b"), (int, float)) and not isinstance(given["b"], bool):
        given["b"] = [given["b"]]
    out = {}
    for p in decl:
        if p.name not in given and p.default is None and not p.optional:
            raise ReplayError(f"{owner}: {p.name} is missing ({p.name} = {p.accepts()}: {p.doc})")
        out[p.name] = p.check(given[p.name], owner) if p.name in given else p.default
    _relations(kind, out, owner)
    return channel, kind, out


def _relations(kind, v, owner):
    if kind == "outliers" and (v["s"] is None) == (v["jump"] is None):
        raise ReplayError(f"{owner}: give either s (a Student-t error's scale) or jump (a fixed jump), not both")
    if kind == "outliers" and v["jump"] is not None and v["df"] is not None:
        raise ReplayError(f"{owner}: df is the Student-t error's (with s), not a fixed jump's")
    if kind == "outliers" and v["s"] is not None and v["df"] is None:
        v["df"] = 3.0
    if kind == "outage" and v["every"] is not None and v["every"] <= v["d"]:
        raise ReplayError(f"{owner}: every = {v['every']:g} s must be longer than the outage d = {v['d']:g} s")
    if kind == "bias" and not v["b"]:
        raise ReplayError(f"{owner}: b must hold one value or one per component (got an empty list)")


def canonical(channel: str, kind: str, values: dict) -> str:
    """``CHANNEL:KIND:NAME=VALUE,...``: every parameter in declaration order, None ones left out."""
    parts = [f"{k}={_num(v)}" for k, v in values.items() if v is not None]
    return f"{channel}:{kind}:" + ",".join(parts)


def _num(v) -> str:
    if isinstance(v, (list, tuple)):
        return "[" + ",".join(_num(x) for x in v) + "]"
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else repr(float(v))


def _split(text: str, where: str) -> tuple[str, str, dict]:
    channel, sep, rest = text.strip().partition(":")
    kind, _, args = rest.partition(":")
    if not sep or not channel or not kind:
        raise ReplayError(f"{where}fault {_show(text)}: expected {HELP}")
    given = {}
    for part in _commas(args):
        name, eq, raw = part.partition("=")
        if not eq or not name.strip():
            raise ReplayError(f"{where}fault {_show(text)}: {shown(part)} is not NAME=VALUE ({HELP})")
        try:
            given[name.strip()] = json.loads(raw)
        except ValueError:
            raise ReplayError(f"{where}fault {_show(text)}: {name.strip()}={shown(raw)} is not a number") from None
    return channel.strip(), kind.strip(), given


def _commas(args: str) -> list[str]:
    """``args`` split at the commas outside brackets (``b=[1,0,0],t0=5``)."""
    out, depth, start = [], 0, 0
    for i, ch in enumerate(args):
        depth += ch == "["
        depth -= ch == "]"
        if ch == "," and depth == 0:
            out.append(args[start:i])
            start = i + 1
    out.append(args[start:])
    return [a.strip() for a in out if a.strip()]


def _show(item) -> str:
    return shown(item) if not isinstance(item, dict) else shown(json.dumps(item, sort_keys=True))


def _where(owner: str) -> str:
    return f"{owner}: " if owner else ""
