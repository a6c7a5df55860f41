"""One entry point for every trajectory source: :func:`load` of a file or ``RECORDING:topic``.

A source is

* a trajectory file (:mod:`replay.trajectory.files`: TUM, KITTI, EuRoC, CSV);
* ``RECORDING:TOPIC`` — a ROS 1 ``.bag``, a ROS 2 bag directory (or its ``.db3``) or an
  ``.mcap`` file, and a topic of a pose type (:mod:`replay.trajectory.bag`);
* ``RECORDING:tf:PARENT->CHILD`` — a transform from ``/tf`` and ``/tf_static``.

The recording path is the longest prefix before a ``:`` that exists as a file or
directory, so paths holding ``:`` still work.
"""

from __future__ import annotations

from pathlib import Path

from replay.trajectory import bag, files
from replay.trajectory.base import Trajectory
from replay.util.errors import DataError

RECORDING_SUFFIXES = (".bag", ".mcap", ".db3")


def split(spec: str):
    """(path, topic or None): ``topic`` when ``spec`` is ``RECORDING:TOPIC``."""
    spec = str(spec)
    need_topic = "a recording needs a topic: RECORDING:TOPIC (or RECORDING:tf:PARENT->CHILD)"
    whole = Path(spec)
    if whole.exists():
        if whole.is_dir() or whole.suffix.lower() in RECORDING_SUFFIXES:
            raise DataError(spec, need_topic)
        return whole, None
    cuts = [i for i, ch in enumerate(spec) if ch == ":"]
    for i in reversed(cuts):
        head = Path(spec[:i])
        if head.exists() and (head.is_dir() or head.suffix.lower() in RECORDING_SUFFIXES):
            return head, spec[i + 1 :]
    for i in cuts:
        if Path(spec[:i]).suffix.lower() in RECORDING_SUFFIXES:
            raise DataError(spec[:i], "no such file")
    return whole, None


def load(
    spec,
    *,
    fmt: str | None = None,
    kitti_times=None,
    columns=None,
    time_unit: str | None = None,
    name: str = "",
    rec=None,
    exact: bool = False,
) -> Trajectory:
    """The trajectory of ``spec`` (module docstring); ``fmt``, ``kitti_times``, ``columns`` and
    ``time_unit`` apply to files (:func:`replay.trajectory.files.read`); ``rec``: the recording,
    when already read (:func:`load_all`); ``exact``: files keep their stamps in integer ns too
    (:mod:`replay.trajectory.stamps`; recordings always do)."""
    path, topic = split(spec)
    if topic is None:
        return files.read(
            path,
            fmt=fmt,
            kitti_times=kitti_times,
            columns=columns,
            time_unit=time_unit,
            name=name or path.name,
            exact=exact,
        )
    if not topic:
        raise DataError(spec, "empty topic after ':'")
    if topic.startswith(("tf:", "/tf:")):
        parent, child = bag.parse_tf(topic.split(":", 1)[1])
        return bag.read_tf(path, parent, child, name=name, rec=rec)
    return bag.read_topic(path, topic, name=name, rec=rec)


def load_all(specs, *, names=None, columns_of: dict | None = None, **options) -> list:
    """:func:`load` of every spec, reading each recording once for all its topics; ``columns_of``:
    {spec: columns} for the files whose columns differ from ``options["columns"]`` (per-file ``--columns``)."""
    wanted = {}
    for spec in specs:
        path, topic = split(spec)
        if topic:
            wanted.setdefault(path.resolve(), set()).update(bag.topics_of(topic))
    recs = {p: bag.read_recording(p, sorted(t)) for p, t in wanted.items()}
    out = []
    for k, spec in enumerate(specs):
        path, topic = split(spec)
        opts = dict(options, columns=columns_of[spec]) if columns_of and spec in columns_of else options
        out.append(load(spec, name=names[k] if names else "", rec=recs.get(path.resolve()) if topic else None, **opts))
    return out


def split_columns(values, specs) -> tuple:
    """(columns for every file, {spec: columns}) of repeated ``--columns`` values: ``FILE=SPEC`` (FILE one
    of ``specs`` as given, or its file name) declares one file's columns, a plain ``SPEC`` the others'."""
    common, per = None, {}
    names = {Path(str(s)).name: s for s in specs}
    for value in values or ():
        head, _, rest = str(value).partition("=")
        spec = head if head in map(str, specs) else names.get(head)
        if spec is not None and rest:
            if spec in per:
                raise DataError("--columns", f"{head}: given twice")
            per[spec] = rest
        elif common is not None:
            raise DataError("--columns", f"{value!r}: a second --columns for every file (give FILE=SPEC for one file)")
        else:
            common = value
    return common, per


def label(spec) -> str:
    """A short name for a source: the file name, or ``RECORDING:TOPIC`` with the file name only."""
    path, topic = split(spec)
    return path.name if topic is None else f"{path.name}:{topic}"
