"""Trajectory conversion (``replay convert``, evo_traj's ``--save_as_tum``/``--save_as_kitti``): write a
:class:`Trajectory` as TUM, KITTI (+ ``times.txt``), EuRoC CSV, a plain CSV with a header, or MCAP.

| format | written | read back by |
|---|---|---|
| ``tum`` | ``t x y z qx qy qz qw``, ``#`` header line | :func:`replay.trajectory.files.read_tum` |
| ``kitti`` | the 3x4 ``[R p]`` row by row; the stamps in ``times.txt`` beside it | :func:`.files.read_kitti` |
| ``euroc`` | ``#timestamp [ns],p_RS_R_x [m],...,q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []``, stamps in integer ns | :func:`.files.read_euroc` |
| ``csv`` | ``t,x,y,z,qx,qy,qz,qw`` (``t,x,y,z`` for positions only), seconds | :func:`.files.read` (by the header) |
| ``mcap`` | ``geometry_msgs/msg/PoseStamped`` (ROS 2 CDR, the definition in the schema) on one topic, ``header.stamp`` and log time the pose's stamp in ns | ``FILE.mcap:/topic`` |

Numbers are written in full (the shortest text that reads back as the same float), so a file read
back gives the numbers written: positions exactly, orientations to rounding (the reader normalises
quaternions; KITTI stores rotation matrices). Stamps survive to the nanosecond in every format
(:mod:`replay.trajectory.stamps`): EuRoC and MCAP write integer nanoseconds, the seconds formats
each stamp's shortest float text, or ``SEC.NNNNNNNNN`` where that text would be another ns
(``1403636579758555392`` ns is written ``1403636579.758555392``, not ``1403636579.7585554``). A trajectory without orientations (NavSatFix) is
written only as CSV: the other formats would need an orientation it does not have. The covariance is
not written.
"""  # noqa: E501 (Markdown table)

from __future__ import annotations

import numpy as np

from replay.trajectory import quat, stamps
from replay.trajectory.base import Trajectory
from replay.util.errors import ReplayError
from pathlib import Path
from replay.util.regular import read_bytes
from mcap.writer import CompressionType, Writer
from rosbags.typesys import Stores, get_typestore

FORMATS = ("tum", "kitti", "euroc", "csv", "mcap")
SUFFIXES = {".tum": "tum", ".txt": "tum", ".kitti": "kitti", ".csv": "csv", ".mcap": "mcap"}
EUROC_HEADER = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"


def fmt_of(path, fmt: str | None) -> str:
    """The output format: ``fmt``, else the extension's (.tum/.txt TUM, .kitti, .csv plain CSV, .mcap)."""
    if fmt is not None:
        if fmt not in FORMATS:
            raise ReplayError(f"--format {fmt!r}: expected one of {', '.join(FORMATS)}")
        return fmt
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise ReplayError(
            f"{path}: the extension {suffix or '(none)'} does not say the format: give --format {'|'.join(FORMATS)}"
        )
    return SUFFIXES[suffix]


def check(tr: Trajectory, fmt: str) -> None:
    if tr.q is None and fmt != "csv":
        raise ReplayError(
            f"{tr.source or tr.name}: positions only (no orientation): {fmt} needs one; write --format csv (t, x, y, z)"
        )
    if fmt in ("euroc", "mcap"):
        stamps.ns_of(tr)  # integer ns: refused beyond int64


def _lines(m: np.ndarray, sep: str = " ") -> str:
    return "".join(sep.join(map(repr, row)) + "\n" for row in m.tolist())


def _stamped(first, m: np.ndarray, sep: str = " ") -> str:
    """Lines of a stamp's text (or integer) then the row of ``m``."""
    return "".join(f"{k}{sep}" + sep.join(map(repr, row)) + "\n" for k, row in zip(first, m.tolist()))


def text(tr: Trajectory, fmt: str) -> str:
    """The file content of ``tr`` as ``tum``, ``kitti`` (poses only: :func:`kitti_times`), ``euroc`` or ``csv``."""
    check(tr, fmt)
    if fmt == "tum":
        return "# t x y z qx qy qz qw\n" + _stamped(stamps.seconds_text(tr), np.column_stack([tr.p, tr.q]))
    if fmt == "kitti":
        R = quat.to_matrix(tr.q)
        return _lines(np.concatenate([R, tr.p[:, :, None]], axis=2).reshape(-1, 12))
    if fmt == "euroc":
        body = np.column_stack([tr.p, tr.q[:, [3, 0, 1, 2]]])
        return EUROC_HEADER + "\n" + _stamped(stamps.ns_of(tr).tolist(), body, ",")
    if fmt == "csv":
        cols = [tr.t, tr.p] + ([tr.q] if tr.q is not None else [])
        head = "t,x,y,z" + (",qx,qy,qz,qw" if tr.q is not None else "")
        return head + "\n" + _stamped(stamps.seconds_text(tr), np.column_stack(cols[1:]), ",")
    raise ReplayError(f"format {fmt!r}: not a text format")


def kitti_times(tr: Trajectory) -> str:
    """The ``times.txt`` of KITTI poses: one stamp (s) per line, to the ns (:mod:`.stamps`)."""
    return "".join(s + "\n" for s in stamps.seconds_text(tr))


def refuse_other_times(times, tr: Trajectory) -> None:
    """Refuse a ``times.txt`` that exists and holds other stamps than ``tr``'s: it belongs to other KITTI
    poses in that directory, which it would re-time (``replay convert --force`` replaces it)."""
    p = Path(times)
    if not p.is_file():
        return
    try:
        held = stamps.of_text(read_bytes(p, "a times file").decode("utf-8", "replace").split())
    except OSError:
        held = None
    same = held is not None and stamps.fits(tr.t) and np.array_equal(held, stamps.ns_of(tr))
    if not same:
        raise ReplayError(
            f"{times}: exists and holds other stamps (it may time other KITTI poses in {p.parent}): refusing to "
            "overwrite it; write OUT into another directory, or give --force to replace it"
        )


def write_mcap(path, tr: Trajectory, *, topic: str = "/pose", frame_id: str = "map") -> int:
    """``tr`` as ``geometry_msgs/msg/PoseStamped`` messages on ``topic`` of a new MCAP file; returns the count."""
    check(tr, "mcap")
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    name = "geometry_msgs/msg/PoseStamped"
    ns = stamps.ns_of(tr)
    with open(path, "wb") as fh:
        w = Writer(fh, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="replay")
        schema = w.register_schema(
            name=name, encoding="ros2msg", data=ts.generate_msgdef(name, ros_version=2)[0].encode()
        )
        channel = w.register_channel(topic=topic, message_encoding="cdr", schema_id=schema)
        for k, (stamp, p, q) in enumerate(zip(ns.tolist(), tr.p.tolist(), tr.q.tolist())):
            sec, nsec = divmod(stamp, 1_000_000_000)
            header = T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame_id
            )
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
            )
            msg = T[name](header=header, pose=pose)
            w.add_message(
                channel, log_time=stamp, publish_time=stamp, data=bytes(ts.serialize_cdr(msg, name)), sequence=k
            )
        w.finish()
    return len(tr)
