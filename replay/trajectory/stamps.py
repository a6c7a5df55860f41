"""Stamps to the nanosecond: read exactly from text or a ROS header, written back exactly (``replay convert``).

A float of seconds near 1.4e9 s is spaced 238 ns apart, and ``t * 1e9`` rounds again, so a stamp carried
as a float loses up to ~180 ns on its way from a EuRoC file (integer ns) to another file. The readers
asked for exact stamps (``exact=True``: ``replay convert``) also keep each stamp in integer nanoseconds
(:attr:`Trajectory.ns`): the decimal text of the file (any number of digits, in its unit, rounded to the
nearest ns, ties to even) or a ROS ``header.stamp`` (``sec``, ``nanosec``). The writers use them:

* integer-nanosecond formats (EuRoC, MCAP) write :func:`ns_of` — the kept stamps, else the float stamp
  rounded exactly (not ``t * 1e9``) to the nearest ns;
* seconds formats (TUM, KITTI ``times.txt``, CSV) write per stamp (:func:`seconds_text`) the float's
  shortest text when that text is the same nanosecond (the float then reads back exactly too), else the
  nanosecond as ``SEC.NNNNNNNNN`` (exact; read back, the float is the one the source's text gave).

So integer nanoseconds round-trip through every format, and float stamps of sources without text stamps
(simulations, DataFrames) are written as before.
"""

from __future__ import annotations

from decimal import ROUND_HALF_EVEN, Decimal, InvalidOperation

import numpy as np
from replay.util.errors import DataError

NS = 10**9
TOL_NS = 1000  # kept stamps further than this from the float stamps are not the trajectory's (never used)
LIMIT = 2**63 - 1  # int64 nanoseconds: +-9.2e9 s (the years 1677-2262)


def _ns(value: Decimal) -> int:
    n = int(value.to_integral_value(rounding=ROUND_HALF_EVEN))
    if abs(n) > LIMIT:
        raise OverflowError(f"{n} ns")
    return n


def of_text(tokens, ns_per_unit: int | Decimal = NS) -> np.ndarray | None:
    """Integer nanoseconds of stamp texts in a unit of ``ns_per_unit`` ns; None when one is not a number."""
    scale = Decimal(ns_per_unit)
    try:
        return np.array([_ns(Decimal(str(tok).strip()) * scale) for tok in tokens], dtype=np.int64)
    except (InvalidOperation, ValueError, OverflowError):
        return None


def of_header(stamps) -> np.ndarray:
    """Integer nanoseconds of ROS ``header.stamp`` values."""
    return np.array([s.sec * NS + s.nanosec for s in stamps], dtype=np.int64)


def per_unit(factor: float) -> Decimal:
    """Nanoseconds per unit of a factor to seconds (1, 1e-3, 1e-6, 1e-9)."""
    return Decimal(repr(float(factor))) * NS


def of_floats(t) -> np.ndarray:
    """Float seconds rounded exactly to the nearest ns (``OverflowError`` beyond int64 ns: :func:`fits`)."""
    return np.array([_ns(Decimal(x) * NS) for x in np.asarray(t, float).tolist()], dtype=np.int64)


def fits(t) -> bool:
    """Whether every stamp (s) is within integer nanoseconds (int64: the years 1677-2262)."""
    return bool(np.all(np.abs(np.asarray(t, float)) < LIMIT / NS))


def ns_of(tr) -> np.ndarray:
    """The stamps of ``tr`` in integer ns: the kept ones (:attr:`Trajectory.ns`) when they are the
    trajectory's, else :func:`of_floats`; a stamp beyond int64 ns is refused in one line naming the source."""
    if not fits(tr.t):
        top = float(np.max(np.abs(tr.t)))
        raise DataError(
            tr.source or tr.name,
            f"a stamp of {top:.6g} s is beyond integer nanoseconds (|t| < 9.2e9 s, the years 1677-2262): "
            "write it in seconds (tum, kitti, csv)",
        )
    exact = of_floats(tr.t)
    kept = getattr(tr, "ns", None)
    if kept is not None and len(kept) == len(exact) and np.all(np.abs(kept - exact) <= TOL_NS):
        return np.asarray(kept, np.int64)
    return exact


def _decimal(n: int) -> str:
    sign, n = ("-", -n) if n < 0 else ("", n)
    sec, frac = divmod(n, NS)
    return f"{sign}{sec}.{frac:09d}"


def seconds_text(tr) -> list[str]:
    """Each stamp of ``tr`` as seconds text that reads back as the same nanosecond (module docstring)."""
    if not fits(tr.t):  # beyond integer ns: the float's shortest text, as it is
        return [repr(x) for x in np.asarray(tr.t, float).tolist()]
    out = []
    for x, n in zip(np.asarray(tr.t, float).tolist(), ns_of(tr).tolist()):
        short = repr(x)
        out.append(short if _ns(Decimal(short) * NS) == n else _decimal(n))
    return out
