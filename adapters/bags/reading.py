"""Opening a recording: ROS 1 ``.bag`` and ROS 2 bag directories through rosbags; MCAP by :mod:`.mcap_reader`."""

from __future__ import annotations

import re
from pathlib import Path

from replay.util.errors import DataError
from replay.util.regular import check_regular

from .. import rosmsg
from .mcap_reader import _read_mcap
from .recording import Recording, Topic, _reason


def recording_kind(path: Path) -> str:
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return "ros2"
        raise DataError(path, "a directory that is not a ROS 2 bag (no metadata.yaml)")
    suffix = path.suffix.lower()
    if suffix == ".bag":
        return "ros1"
    if suffix == ".mcap":
        return "mcap"
    if suffix == ".db3":
        return "ros2"
    raise DataError(path, f"not a bag or MCAP file (extension {suffix or '(none)'!r})")


def read(path, topics=None, until: float | None = None, first_only: bool = False) -> Recording:
    """Open a recording; deserialize the messages of ``topics`` (all when None, none when []).

    ``topics`` may also be a function ``{topic: (type, count)} -> list of topics``,
    called once the topics are known (ROS bags; for MCAP after the single pass).
    ``first_only`` deserializes only the first message of each topic (log times of all).
    """
    path = Path(path).expanduser()
    if not path.exists():
        raise DataError(path, "no such file or directory")
    check_regular(path, "a recording", dir_ok=True)  # a FIFO or a device never ends
    for entry in sorted(path.iterdir()) if path.is_dir() else ():  # nor inside a ROS 2 bag directory
        check_regular(entry, "a file of a ROS 2 bag", dir_ok=True)
    kind = recording_kind(path)
    if path.is_file() and path.stat().st_size == 0:
        raise DataError(path, "empty file (0 bytes): not a recording")
    if kind == "ros2" and path.is_file():
        path = path.parent
    if kind == "mcap":
        return _read_mcap(path, topics, until, first_only)
    return _read_rosbags(path, kind, topics, until, first_only)


def _read_rosbags(path: Path, kind: str, topics, until, first_only=False) -> Recording:
    # lazy: start-up, every adapter imports the bags package and so this module: rosbags.highlevel measured ~220 ms
    from rosbags.highlevel import AnyReader  # noqa: PLC0415
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415

    rec = Recording(path, kind, {}, None, None)
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as e:  # noqa: BLE001 - any reader failure is bad input here
        raise DataError(
            path, f"cannot open ({_reason(e)}); the file is truncated, corrupted or not a bag; no message could be read"
        ) from None
    try:
        if kind == "ros2":
            found = re.search(r"storage_identifier:\s*(\w+)", (path / "metadata.yaml").read_text())
            rec.format = f"ros2-{found.group(1) if found else 'bag'}"
        rec.start_ns, rec.end_ns = int(reader.start_time), int(reader.end_time)
        for c in reader.connections:
            t = rec.topics.setdefault(c.topic, Topic(c.topic, rosmsg.normalize_type(c.msgtype)))
            t.count += int(c.msgcount)
        if callable(topics):
            topics = topics({t.name: (t.type, t.count) for t in rec.topics.values()})
        wanted = [c for c in reader.connections if topics is None or c.topic in topics]
        limit = None if until is None else rec.start_ns + int(round(until * 1e9))
        current = None
        try:
            if wanted:
                for conn, log_ns, raw in reader.messages(connections=wanted):
                    current = conn.topic
                    if limit is not None and log_ns > limit:
                        break
                    topic = rec.topics[conn.topic]
                    topic.log_ns.append(log_ns)
                    if not (first_only and topic.msgs):
                        topic.msgs.append(reader.deserialize(raw, conn.msgtype))
                    rec.read_messages += 1
        except Exception as e:  # noqa: BLE001
            rec.truncated = f"reading stopped on topic {current or '?'}: {_reason(e)}"
    finally:
        try:
            reader.close()
        except Exception:  # noqa: BLE001
            pass
    return rec
