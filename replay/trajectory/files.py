"""Trajectory files: TUM, KITTI poses, EuRoC ground truth, and plain CSV with declared columns.

| format | layout | stamps |
|---|---|---|
| ``tum`` | ``t x y z qx qy qz qw`` per line, separated by spaces (or tabs); ``#`` comments | seconds |
| ``kitti`` | 12 numbers per line: the rows of the 3x4 matrix [R p] (R maps body to world) | a times file: one stamp (s) per line, ``times.txt`` beside the poses or named (``kitti_times``); without one the file is refused |
| ``euroc`` | CSV ``#timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z, ...`` (``state_groundtruth_estimate0/data.csv``, at least 8 columns; quaternion w first) | nanoseconds |
| ``csv`` | a CSV (``,`` ``;`` or spaces); ``columns`` maps ``t, x, y, z`` and either ``qx, qy, qz, qw`` or ``roll, pitch, yaw`` (rad; or ``yaw`` alone) to header names or 0-based indices; ``z`` may be absent (0); without ``columns``, the header's names (:mod:`.layout`) | ``time_unit`` (s, ms, us, ns), else the header's unit, else s |

Which format and column order a file has is decided by :func:`replay.trajectory.layout.decide`:
the header's names first, never the position of the columns alone; an ambiguous file is refused.
A FIFO or a device is refused before it is read (:mod:`replay.util.regular`).

Every data line must have the format's number of columns (error: the line number and the
counts); numbers must parse; then :func:`replay.trajectory.base.make` checks stamps and
quaternions. KITTI rotation matrices must be rotations (R'R = I within 1e-3, det > 0) and are
stored as quaternions: the nearest rotation, so files printed with 6 digits are
orthonormalised (evo keeps the printed matrices; rotation statistics then differ from
evo's in about the 6th digit).
"""  # noqa: E501 (Markdown tables)

from __future__ import annotations

import io
import warnings

from pathlib import Path

import numpy as np

from dataclasses import replace

from replay.trajectory import layout, quat, stamps
from replay.trajectory.base import Trajectory, make
from replay.trajectory.layout import TIME_UNITS
from replay.util.errors import DataError
from replay.util.regular import read_bytes
from replay.adapters.rosmsg import rpy_to_quat

FORMATS = ("tum", "kitti", "euroc", "csv")
ROT_TOL = 1e-3


def _text(path: Path) -> str:
    try:
        raw = read_bytes(path, "a trajectory file")
    except FileNotFoundError:
        raise DataError(path, "no such file") from None
    except OSError as e:
        raise DataError(path, f"cannot read ({e.strerror or e})") from None
    if not raw.strip():
        raise DataError(path, "empty file: no poses")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise DataError(path, "not a text file (not UTF-8)") from None


def _rows(path: Path, sep: str | None, comment: str = "#", header: bool = False):
    """(line numbers, list of token lists, header tokens or None) of the data lines. With ``header``,
    non-numeric lines before the first data line are header candidates too; the header is the last
    candidate with as many names as the first data line has columns, else the first candidate."""
    lines = _text(path).splitlines()
    numbers, tokens, before = [], [], []
    for k, line in enumerate(lines, start=1):
        s = line.strip()
        if not s:
            continue
        if s.startswith(comment) or (header and not numbers and not _numeric(s, sep)):
            if not numbers:
                before.append([c.strip() for c in s.lstrip(comment).split(sep)])
            continue
        numbers.append(k)
        tokens.append([c.strip() for c in s.split(sep)] if sep else s.split())
    width = len(tokens[0]) if tokens else -1
    head = next((h for h in reversed(before) if len(h) == width), before[0] if before else None)
    return np.array(numbers), tokens, head


def _numeric(s: str, sep) -> bool:
    try:
        float((s.split(sep) if sep else s.split())[0])
        return True
    except ValueError:
        return False


def _matrix(path: Path, numbers, tokens, ncols: int | None, what: str, min_cols: int = 1) -> np.ndarray:
    """The data lines as floats: each with ``ncols`` columns (None: as many as the first line, at
    least ``min_cols``); else the first offending line is refused."""
    if not tokens:
        raise DataError(path, f"no data lines: expected {what}")
    counts = np.fromiter((len(r) for r in tokens), int, len(tokens))
    want = ncols if ncols is not None else int(counts[0])
    if want < min_cols:
        raise DataError(path, f"{want} columns, expected at least {min_cols} ({what})", row=int(numbers[0]))
    bad = counts != want
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        expected = f"{want}" if ncols is not None else f"{want} as on line {numbers[0]}"
        raise DataError(path, f"{counts[i]} columns, expected {expected} ({what})", row=int(numbers[i]))
    try:
        return np.array(tokens, dtype=float)
    except ValueError:
        for i, r in enumerate(tokens):
            for c, v in enumerate(r):
                try:
                    float(v)
                except ValueError:
                    raise DataError(path, f"column {c + 1}: {v[:40]!r} is not a number", row=int(numbers[i])) from None
        raise


def _first_column(path: Path, numbers, sep: str | None = None):
    """The first token of each data line (``numbers``: their line numbers): the stamps' text."""
    lines = _text(path).splitlines()
    return [(lines[k - 1].split(sep) if sep else lines[k - 1].split())[0] for k in numbers]


def _exact(tr: Trajectory, tokens, ns_per_unit=stamps.NS) -> Trajectory:
    """``tr`` keeping its stamps in integer ns as the text gives them (:mod:`.stamps`)."""
    return replace(tr, ns=stamps.of_text(tokens, ns_per_unit)) if tr.ns is None else tr


def read_tum(path, *, name: str = "", exact: bool = False) -> Trajectory:
    """``exact``: keep the stamps in integer ns too (:mod:`.stamps`; a second pass over the text)."""
    path = Path(path)
    fast = _fast_matrix(path, 8)
    if fast is None:  # anything irregular: the line-by-line reader, which names the line
        numbers, tokens, _ = _rows(path, None)
        fast = numbers, _matrix(path, numbers, tokens, 8, "TUM: t x y z qx qy qz qw")
    numbers, m = fast
    tr = make(m[:, 0], m[:, 1:4], m[:, 4:8], source=path, name=name, rows=numbers)
    return _exact(tr, _first_column(path, numbers)) if exact else tr


def _fast_matrix(path: Path, ncols: int):
    """(line numbers, matrix) of a regular whitespace-separated file of ``ncols`` numbers per data line
    (``#`` comment lines, blank lines) in one pass of numpy's C parser, equal to the line-by-line
    reader's values (both correctly rounded); None when anything is irregular (an inline ``#``, a
    wrong column count, a token that is not a number), so that the line-by-line reader refuses it
    naming the line."""
    text = _text(path)
    numbers = []
    for k, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if s and not s.startswith("#"):
            if "#" in s:
                return None
            numbers.append(k)
    if not numbers:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            m = np.loadtxt(io.StringIO(text), comments="#", ndmin=2, dtype=float)
    except (ValueError, UserWarning):
        return None
    return (np.array(numbers), m) if m.shape == (len(numbers), ncols) else None


def kitti_times_path(path: Path, times=None) -> Path:
    """The times file of KITTI poses: ``times`` if given, else ``times.txt`` beside them; refused when absent."""
    if times is not None:
        return Path(times)
    beside = path.parent / "times.txt"
    if beside.is_file():
        return beside
    raise DataError(
        path,
        "KITTI poses carry no stamps: give a times file (--kitti-times FILE, one stamp in "
        "seconds per line, or times.txt beside the poses)",
    )


def read_kitti(path, *, times=None, name: str = "", exact: bool = False) -> Trajectory:
    path = Path(path)
    numbers, tokens, _ = _rows(path, None)
    m = _matrix(path, numbers, tokens, 12, "KITTI: the 3x4 matrix [R p] row by row")
    tpath = kitti_times_path(path, times)
    tn, tt, _ = _rows(tpath, None)
    stamps = _matrix(tpath, tn, tt, 1, "one stamp in seconds per line")[:, 0]
    if len(stamps) != len(m):
        raise DataError(tpath, f"{len(stamps)} stamps for the {len(m)} poses of {path}")
    M = m.reshape(-1, 3, 4)
    R = M[:, :, :3]
    err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = ~((err <= ROT_TOL) & (det > 0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataError(
            path,
            f"the 3x3 block is not a rotation (|R'R - I| = {err[i]:.3g}, det = {det[i]:.6g}; tolerance {ROT_TOL:g})",
            row=int(numbers[i]),
        )
    tr = make(stamps, M[:, :, 3], quat.from_matrix(R), source=path, name=name, rows=numbers)
    return _exact(tr, [r[0] for r in tt]) if exact else tr


def read_euroc(path, *, name: str = "", exact: bool = False) -> Trajectory:
    path = Path(path)
    numbers, tokens, _ = _rows(path, ",")
    m = _matrix(
        path, numbers, tokens, None, "EuRoC: timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z, ...", min_cols=8
    )
    q = m[:, [5, 6, 7, 4]]
    tr = make(m[:, 0] / 1e9, m[:, 1:4], q, source=path, name=name, rows=numbers)
    return _exact(tr, [r[0] for r in tokens], 1) if exact else tr


def parse_columns(spec) -> dict:
    """``"t=time,x=px,..."`` or a dict -> {field: header name or 0-based index}."""
    if isinstance(spec, dict):
        items = spec.items()
    else:
        items = []
        for part in str(spec).split(","):
            if not part.strip():
                continue
            if "=" not in part:
                raise DataError("--columns", f"{part.strip()!r}: expected FIELD=COLUMN (e.g. t=timestamp)")
            k, v = part.split("=", 1)
            items.append((k.strip(), v.strip()))
    known = ("t", "x", "y", "z", "qx", "qy", "qz", "qw", "roll", "pitch", "yaw")
    out = {}
    for k, v in items:
        if k not in known:
            raise DataError("--columns", f"unknown field {k!r}: expected some of {', '.join(known)}")
        out[k] = int(v) if isinstance(v, int) or str(v).isdigit() else str(v)
    missing = [k for k in ("t", "x", "y") if k not in out]
    if missing:
        raise DataError("--columns", f"missing {', '.join(missing)}: t, x and y are required")
    qs = [k for k in ("qx", "qy", "qz", "qw") if k in out]
    if qs and len(qs) != 4:
        raise DataError("--columns", "a quaternion needs all of qx, qy, qz, qw")
    if qs and any(k in out for k in ("roll", "pitch", "yaw")):
        raise DataError("--columns", "give either a quaternion or roll/pitch/yaw, not both")
    if any(k in out for k in ("roll", "pitch")) and "yaw" not in out:
        raise DataError("--columns", "roll/pitch without yaw")
    return out


def read_csv(
    path,
    *,
    columns,
    time_unit: str | None = None,
    name: str = "",
    header_unit: str | None = None,
    exact: bool = False,
) -> Trajectory:
    """A CSV (``,`` or ``;``; or whitespace) of declared ``columns``; stamps in ``time_unit``, else in the
    unit the header names (``header_unit``), else seconds where they can be (:func:`layout.seconds`)."""
    path = Path(path)
    cols = parse_columns(columns)
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise DataError(path, f"time unit {time_unit!r}: expected one of {', '.join(TIME_UNITS)}")
    text = _text(path)
    sep = layout.sniff(text).sep
    numbers, tokens, head = _rows(path, sep, header=True)
    m = _matrix(path, numbers, tokens, None, "every line as many columns as the first")
    index = {}
    for field, c in cols.items():
        if isinstance(c, int):
            if c >= m.shape[1]:
                raise DataError(path, f"--columns {field}={c}: the file has {m.shape[1]} columns")
            index[field] = c
        elif head is None or c not in head:
            raise DataError(
                path,
                f"--columns {field}={c}: no column {c!r} in the header "
                f"({', '.join(head) if head else 'the file has no header'})",
            )
        else:
            index[field] = head.index(c)
    col = lambda k: m[:, index[k]]  # noqa: E731
    p = np.column_stack([col("x"), col("y"), col("z") if "z" in index else np.zeros(len(m))])
    q = None
    if "qw" in index:
        q = np.column_stack([col("qx"), col("qy"), col("qz"), col("qw")])
    elif "yaw" in index:
        zero = np.zeros(len(m))
        q = rpy_to_quat(
            np.column_stack(
                [col("roll") if "roll" in index else zero, col("pitch") if "pitch" in index else zero, col("yaw")]
            )
        )
    tname = head[index["t"]] if head is not None and index["t"] < len(head) else f"column {index['t'] + 1}"
    factor = layout.seconds(path, col("t"), tname, header_unit, time_unit)
    tr = make(col("t") * factor, p, q, source=path, name=name, rows=numbers)
    return _exact(tr, [r[index["t"]] for r in tokens], stamps.per_unit(factor)) if exact else tr


def read(
    path,
    *,
    fmt: str | None = None,
    kitti_times=None,
    columns=None,
    time_unit: str | None = None,
    name: str = "",
    exact: bool = False,
) -> Trajectory:
    """Read a trajectory file of format ``fmt`` (``csv`` when ``columns`` are given; else decided by
    :func:`replay.trajectory.layout.decide`: the header's names, then the layouts TUM and KITTI
    have alone; an ambiguous file is refused naming the choices). ``time_unit``: of a CSV's stamps
    (default: the unit its header names, else seconds); ``exact``: keep the stamps in integer ns too."""
    path = Path(path)
    if not path.exists():
        raise DataError(path, "no such file")
    if fmt is not None and fmt not in FORMATS:
        raise DataError(path, f"format {fmt!r}: expected one of {', '.join(FORMATS)}")
    header_unit = None
    if fmt is None and columns is not None:
        fmt = "csv"
    by = "--format"
    if fmt is None and path.suffix.lower() in (".tum", ".kitti"):
        fmt, by = path.suffix.lower()[1:], f"the extension {path.suffix}"
    if fmt != "kitti" and columns is None:
        fmt, columns, header_unit = layout.decide(path, _text(path), fmt, by)
    elif fmt == "csv":
        header_unit = layout.check_columns(path, _text(path), parse_columns(columns))
    if fmt == "csv" and columns is None:
        raise DataError(path, "a plain CSV needs its columns declared (--columns t=...,x=...,y=...,z=...,qx=...)")
    if fmt == "tum":
        return read_tum(path, name=name, exact=exact)
    if fmt == "kitti":
        return read_kitti(path, times=kitti_times, name=name, exact=exact)
    if fmt == "euroc":
        return read_euroc(path, name=name, exact=exact)
    return read_csv(path, columns=columns, time_unit=time_unit, name=name, header_unit=header_unit, exact=exact)


def write_tum(path, traj: Trajectory) -> None:
    """``traj`` as a TUM file (17 significant digits)."""
    q = traj.q if traj.q is not None else np.tile([0.0, 0.0, 0.0, 1.0], (len(traj), 1))
    np.savetxt(path, np.column_stack([traj.t, traj.p, q]), fmt="%.17g")
