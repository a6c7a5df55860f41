"""The column layout of a trajectory text file: decided by its header's names, never by position alone.

A TUM file and a CSV of ``t, x, y, z, qx, qy, qz, qw`` hold the quaternion x first; EuRoC's
ground truth holds it w first (``#timestamp, p_RS_R_x [m], ..., q_RS_w [], q_RS_x [], ...``).
Read in the wrong order, every rotation is another valid rotation and every rotation number is
wrong. So :func:`decide`:

* a header (the last ``#`` comment line, or a first non-numeric line, before the first data
  line that has as many names as that line has columns) whose names identify the time, position
  and quaternion columns decides: the reader follows the names (``qx, qy, qz, qw`` and
  ``q_RS_w [], q_RS_x [], ...`` alike), the time unit is the one the header names (``[ns]``,
  ``(s)``, ``_ms``), and ``--format tum|euroc`` that contradicts the names is refused;
* without such a header, whitespace-separated lines of 8 columns are TUM and of 12 KITTI
  (those formats have one layout), while a comma-separated file of 8 or more columns could be
  either order and is refused, naming the choices (``--format euroc``, ``--columns ...``);
* a header that names a column twice, part of a quaternion, or Euler angles is refused: the
  columns are then declared with ``--columns``.

Names are compared in lower case, without units in brackets, split at ``_ . : / -`` and spaces:
the last part is the axis (``x y z w``); parts before it that say ``q``, ``quat``,
``orientation``, ``rot`` make a quaternion component, ``p``, ``pos``, ``position``, ``t``,
``trans``, ``pose`` (or none) a position; others (EuRoC's velocities and biases) are ignored.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from replay.util.errors import DataError

FIELDS = ("t", "x", "y", "z", "qx", "qy", "qz", "qw")
TUM_ORDER = {f: i for i, f in enumerate(FIELDS)}
EUROC_ORDER = {"t": 0, "x": 1, "y": 2, "z": 3, "qw": 4, "qx": 5, "qy": 6, "qz": 7}
TIME_WORDS = {"t", "time", "timestamp", "stamp", "times", "ts", "sec", "secs"}
POSITION_WORDS = {"p", "pos", "position", "t", "tr", "trans", "translation", "pose", "xyz"}
QUAT_WORDS = {"q", "quat", "quaternion", "orientation", "ori", "rot", "rotation", "att", "attitude"}
ANGLE_WORDS = {"roll", "pitch", "yaw", "heading", "phi", "theta", "psi"}
UNITS = {
    "s": "s",
    "sec": "s",
    "secs": "s",
    "second": "s",
    "seconds": "s",
    "ms": "ms",
    "us": "us",
    "µs": "us",
    "ns": "ns",
    "nsec": "ns",
    "nsecs": "ns",
}
LENGTHS = ("m", "mm", "cm", "km")  # a position column's unit: only m (or none) is read as is
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
NOT_SECONDS = 1e11  # s: a stamp beyond this (year 5138 as Unix time) is not in seconds
EPOCH = (1e8, 1e10)  # s: Unix time from 1973 to 2286, what a stamp of unstated unit is taken for
STEP = (1e-5, 1e3)  # s: ... when the median step between poses is then plausible too
CHOICES = (
    "--format euroc (t [ns], x, y, z, qw, qx, qy, qz), or --columns "
    "t=0,x=1,y=2,z=3,qx=4,qy=5,qz=6,qw=7 (x first; --time-unit), or a header line naming the columns"
)


@dataclass
class Layout:
    """What the text shows: separator, columns of the first data line, header names (or None),
    and, where the names decide, the column of each field and the unit the time column names."""

    sep: str | None
    ncols: int
    names: list | None
    columns: dict = field(default_factory=dict)
    time_unit: str | None = None
    euroc_names: bool = False
    problem: str | None = None  # the header names columns, but not usably (duplicates, half a quaternion)

    @property
    def shown(self) -> str:
        return ", ".join(self.names or ())


def _numeric(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def _split(line: str, sep):
    return [c.strip() for c in line.split(sep)] if sep else line.split()


def _lines(text: str):
    start = 0
    while start < len(text):
        end = text.find("\n", start)
        end = len(text) if end < 0 else end
        yield text[start:end]
        start = end + 1


def role(name: str):
    """(field or ``"angle"`` or None, the unit the name gives or None) of one header name."""
    base = name.strip().lstrip("#").strip().lower()
    unit = None
    m = re.search(r"[\[(]\s*([^\])]*?)\s*[\])]", base)
    if m:
        unit = m.group(1).replace(" ", "") or None
        base = (base[: m.start()] + base[m.end() :]).strip()
    parts = [p for p in re.split(r"[\s_.:/\-]+", base) if p]
    if len(parts) == 1 and re.fullmatch(r"[qpt][xyzw]", parts[0]):
        parts = [parts[0][0], parts[0][1]]
    if len(parts) > 1 and (
        (parts[-1] in UNITS and parts[-2] in TIME_WORDS) or (parts[-1] in LENGTHS and parts[-2] in ("x", "y", "z"))
    ):
        unit, parts = parts[-1], parts[:-1]
    if not parts:
        return None, None
    last, before = parts[-1], set(parts[:-1])
    if last in TIME_WORDS and not (before & (QUAT_WORDS | POSITION_WORDS - {"t"})):
        return "t", unit
    if last in ANGLE_WORDS:
        return "angle", unit
    if last in ("x", "y", "z", "w"):
        if before & QUAT_WORDS or (not before and last == "w"):
            return "q" + last, None
        if not before or before & POSITION_WORDS:
            return (last if last != "w" else None), unit
    return None, None


def sniff(text: str) -> Layout:
    """The :class:`Layout` of a trajectory file's text."""
    first, before = None, []
    for ln in _lines(text):  # lazily: only the lines up to the first data line are looked at
        ln = ln.strip()
        if not ln:
            continue
        if ln.startswith("#") or not _numeric(_split(ln, "," if "," in ln else ";" if ";" in ln else None)[0]):
            if first is None:
                before.append(ln.lstrip("#").strip())
            continue
        first = ln
        break
    if first is None:
        return Layout(None, 0, None)
    sep = "," if "," in first else ";" if ";" in first else None
    ncols = len(_split(first, sep))
    names = next((_split(h, sep) for h in reversed(before) if h and len(_split(h, sep)) == ncols), None)
    lay = Layout(sep, ncols, names)
    if names is None:
        return lay
    found, units = {}, {}
    for i, n in enumerate(names):
        r, u = role(n)
        if r is not None:
            found.setdefault(r, []).append(i)
            units.setdefault(r, u)
    unit = units.get("t")
    badpos = next((names[found[f][0]] for f in "xyz" if units.get(f) not in (None, "m") and f in found), None)
    twice = next((f for f in FIELDS if len(found.get(f, ())) > 1), None)
    quat = [f for f in FIELDS[4:] if f in found]
    if not all(f in found for f in ("t", "x", "y")):
        return lay
    if unit is not None and unit not in UNITS:
        lay.problem = f"the header's time column {names[found['t'][0]]!r} gives the unknown unit {unit!r}"
    elif badpos is not None:
        lay.problem = (
            f"the header's position column {badpos!r} is not in metres, which replay reads: convert the file to metres"
        )
    elif twice:
        lay.problem = f"the header names {twice!r} twice ({', '.join(names[i] for i in found[twice])})"
    elif quat and len(quat) != 4:
        lay.problem = f"the header names part of a quaternion ({', '.join(names[found[f][0]] for f in quat)})"
    elif "angle" in found and not quat:
        lay.problem = f"the header names angles ({', '.join(names[i] for i in found['angle'])}), not a quaternion"
    else:
        lay.columns = {f: found[f][0] for f in FIELDS if f in found}
        lay.time_unit = UNITS.get(unit)
        lay.euroc_names = any("p_rs_r_" in n.lower() or "q_rs_" in n.lower() for n in names)
    return lay


READS = {
    "tum": "'t x y z qx qy qz qw' separated by spaces, stamps in s",
    "euroc": "'timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z' separated by commas",
}


def decide(path, text: str, fmt: str | None, by: str = "--format"):
    """(format, columns or None, time unit the header names or None) of a TUM, EuRoC or CSV file
    (module docstring); ``fmt`` the format named by ``by`` (``--format``, or the file's extension;
    None: none). A header whose names decide the layout overrides nothing: a named format that
    contradicts it is refused. Refusals are one line."""
    lay = sniff(text)
    if lay.problem and fmt not in ("tum", "euroc"):
        raise DataError(
            path,
            lay.problem
            if "metres" in lay.problem
            else f"{lay.problem}: declare the columns "
            "with --columns t=...,x=...,y=...,z=...,qx=...,qy=...,qz=...,qw=... (names or 0-based indices)",
        )
    cols, unit = lay.columns, lay.time_unit
    if cols and not lay.problem:
        tum = cols == TUM_ORDER and lay.sep is None and lay.ncols == 8 and unit in (None, "s")
        euroc = cols == EUROC_ORDER and lay.sep == "," and unit in (None, "ns")
        if (fmt == "tum" and not tum) or (fmt == "euroc" and not euroc):
            who, how = (f"--format {fmt}", "leave out --format") if by == "--format" else (by, "give --format csv")
            raise DataError(
                path,
                f"{who} reads {READS[fmt]}, but the header names {lay.shown}: {how} to read the columns by their names",
            )
        if fmt in ("tum", "euroc"):
            return fmt, None, None
        if euroc and not (unit is None and not lay.euroc_names):  # unit-less: EuRoC's own names say ns
            return "euroc", None, None
        return ("tum", None, None) if tum else ("csv", cols, unit)
    if fmt is not None:
        return fmt, None, None
    if lay.sep is None:
        if lay.ncols == 8:
            return "tum", None, None
        if lay.ncols == 12:
            return "kitti", None, None
        raise DataError(
            path,
            f"cannot tell the format ({lay.ncols} columns on the first data line: TUM has 8, "
            "KITTI 12; a CSV needs --columns); name it with --format",
        )
    if lay.ncols >= 8:
        what = f"a header the columns cannot be told from ({lay.shown})" if lay.names else "no header naming them"
        raise DataError(
            path,
            f"cannot tell the column order ({lay.ncols} columns, {what}): x first "
            f"(t x y z qx qy qz qw) or w first (EuRoC)? choose with {CHOICES}",
        )
    return "csv", None, None


def check_columns(path, text: str, columns: dict) -> str | None:
    """Refuse ``--columns`` given by index that contradict the file's header names (e.g. x-first
    indices on an EuRoC file whose header puts ``q_RS_w`` first): one ``--columns`` for several
    files must not silently misread one of them. Returns the time unit the header names for the
    declared time column (None: none)."""
    lay = sniff(text)
    if not lay.columns or lay.problem:
        return None
    field_of = {i: f for f, i in lay.columns.items()}
    for f, c in columns.items():
        if not isinstance(c, int) or f not in FIELDS:
            continue
        if (f in lay.columns and lay.columns[f] != c) or field_of.get(c, f) != f:
            named = lay.names[c] if c < len(lay.names) else "nothing"
            raise DataError(
                path,
                f"--columns {f}={c}, but the header names column {c} {named!r}"
                + (f" and {f} {lay.names[lay.columns[f]]!r}" if f in lay.columns else "")
                + ": give the columns by name (--columns t=NAME,...) or leave out --columns "
                "to read this file by its header",
            )
    t = columns.get("t")
    t = lay.names.index(t) if isinstance(t, str) and t in lay.names else t
    return lay.time_unit if t == lay.columns["t"] else None


def seconds(path, t, name: str, header_unit, given) -> float:
    """The factor to seconds of a time column: ``given`` (``--time-unit``) or the header's unit (they
    must agree); else the one unit in which the stamps are Unix time (1973-2286: seconds ~1.7e9,
    ms ~1.7e12, us ~1.7e15, ns ~1.7e18; the ranges do not overlap) with a median step between
    10 us and 1000 s; else seconds, refused where the stamps cannot be seconds."""
    if given is not None and header_unit is not None and given != header_unit:
        raise DataError(path, f"--time-unit {given}, but the header's time column {name!r} says {header_unit}")
    unit = given or header_unit
    top = float(abs(t).max()) if len(t) else 0.0
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    if unit is None:
        unit = next(
            (u for u, f in TIME_UNITS.items() if EPOCH[0] <= top * f <= EPOCH[1] and STEP[0] <= step * f <= STEP[1]),
            None,
        )
    if unit is None and top >= NOT_SECONDS:
        raise DataError(
            path,
            f"the time column {name!r} names no unit and its stamps reach {top:.4g}, which are "
            "neither seconds nor Unix time in ms, us or ns: give --time-unit",
        )
    return TIME_UNITS[unit or "s"]
