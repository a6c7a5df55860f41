"""Standalone MCAP files: ROS 2 CDR, Foxglove JSON and protobuf channels, read as one stream."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

from replay.util.errors import DataError

from .. import rosmsg
from .recording import Recording, Topic, _reason


def _read_mcap(path: Path, topics, until, first_only=False) -> Recording:
    """Stream every record (so a truncated file yields what precedes the damage)."""
    # lazy: start-up, every adapter imports the bags package and so this module (mcap, rosbags, protobuf: ~110 ms)
    from mcap.stream_reader import StreamReader  # noqa: PLC0415
    from mcap.records import Channel as McChannel, Message, Schema  # noqa: PLC0415

    rec = Recording(path, "mcap", {}, None, None)
    schemas, channels, decoders = {}, {}, {}
    pending = []  # (channel id, log_time, data) of wanted messages, decoded after the pass
    current = None
    try:
        with open(path, "rb") as fh:
            for record in StreamReader(fh, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, McChannel):
                    channels[record.id] = record
                    schema = schemas.get(record.schema_id)
                    typ = _mcap_type(schema, record)
                    rec.topics.setdefault(record.topic, Topic(record.topic, typ))
                elif isinstance(record, Message):
                    ch = channels.get(record.channel_id)
                    if ch is None:
                        raise ValueError(f"message on unknown channel id {record.channel_id}")
                    current = ch.topic
                    topic = rec.topics[ch.topic]
                    topic.count += 1
                    rec.start_ns = record.log_time if rec.start_ns is None else min(rec.start_ns, record.log_time)
                    rec.end_ns = record.log_time if rec.end_ns is None else max(rec.end_ns, record.log_time)
                    pending.append((record.channel_id, record.log_time, record.data))
    except Exception as e:  # noqa: BLE001 - truncated / corrupted stream
        where = f" after topic {current}" if current else ""
        rec.truncated = f"reading stopped{where}: {_reason(e)}"
    if not channels and rec.truncated:
        raise DataError(path, f"truncated or corrupted, no channel could be read ({rec.truncated})")
    if any(s.encoding == "ros2msg" for s in schemas.values()) or any(
        c.message_encoding == "cdr" for c in channels.values()
    ):
        rec.format = "mcap-ros2"
    limit = None if until is None or rec.start_ns is None else rec.start_ns + int(round(until * 1e9))
    if callable(topics):
        topics = topics({t.name: (t.type, t.count) for t in rec.topics.values()})
    pending = [m for m in pending if topics is None or channels[m[0]].topic in topics]
    pending.sort(key=lambda m: m[1])  # log-time order, stable
    for cid, log_ns, data in pending:
        if limit is not None and log_ns > limit:
            break
        ch = channels[cid]
        if cid not in decoders:
            decoders[cid] = _decoder(path, schemas.get(ch.schema_id), ch)
        topic = rec.topics[ch.topic]
        if first_only and topic.msgs:
            topic.log_ns.append(log_ns)
            continue
        try:
            msg = decoders[cid](data)
        except Exception as e:  # noqa: BLE001
            raise DataError(path, f"topic {ch.topic}: cannot decode a {topic.type} message ({_reason(e)})") from None
        topic.log_ns.append(log_ns)
        topic.msgs.append(msg)
        rec.read_messages += 1
    return rec


def _mcap_type(schema, channel) -> str:
    if schema is None:
        return "(no schema)"
    return rosmsg.normalize_type(schema.name) if schema.encoding in ("ros2msg", "ros1msg") else schema.name


def _decoder(path, schema, channel):
    enc = channel.message_encoding
    if enc == "cdr":
        return _cdr_decoder(path, schema, channel)
    if enc == "json":
        return lambda data: _foxglove(json.loads(data), proto=False)
    if enc == "protobuf":
        return _protobuf_decoder(path, schema, channel)
    raise DataError(path, f"topic {channel.topic}: message encoding {enc!r} is not supported")


def _cdr_decoder(path, schema, channel):
    # lazy: start-up, every adapter imports the bags package and so this module (mcap, rosbags, protobuf: ~110 ms)
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: PLC0415

    name = rosmsg.normalize_type(schema.name)
    if schema.data:
        store = get_typestore(Stores.EMPTY)
        try:
            store.register(get_types_from_msg(schema.data.decode(), name))
        except Exception as e:  # noqa: BLE001
            raise DataError(
                path, f"topic {channel.topic}: cannot parse the definition of {name} ({_reason(e)})"
            ) from None
    else:  # ROS 2 bags before Iron carry no definitions
        store = get_typestore(Stores.ROS2_HUMBLE)
        if name not in store.fielddefs:
            raise DataError(
                path,
                f"topic {channel.topic}: {name} has no definition in the file nor in the default (humble) typestore",
            )
    return lambda data: store.deserialize_cdr(data, name)


def _protobuf_decoder(path, schema, channel):
    # lazy: start-up, every adapter imports the bags package and so this module (mcap, rosbags, protobuf: ~110 ms)
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory  # noqa: PLC0415

    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    todo, added = list(fds.file), set()
    while todo:  # dependencies first, whatever the order in the set
        ready = [fd for fd in todo if set(fd.dependency) <= added] or todo[:1]
        for fd in ready:
            pool.Add(fd)
            added.add(fd.name)
            todo.remove(fd)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    return lambda data: _foxglove(cls.FromString(data), proto=True)


class _Ns(SimpleNamespace):
    pass


def _ns(obj):
    if isinstance(obj, dict):
        return _Ns(**{k: _ns(v) for k, v in obj.items()})
    return obj


def _foxglove(msg, proto: bool):
    """A Foxglove message with a ROS-like ``header.stamp`` (sec, nanosec) and ``frame_id``."""
    if not proto:
        msg = _ns(msg)
    ts = getattr(msg, "timestamp", None)
    if proto:
        sec, nsec = (ts.seconds, ts.nanos) if ts is not None else (0, 0)
    else:
        sec, nsec = (getattr(ts, "sec", 0), getattr(ts, "nsec", 0)) if ts is not None else (0, 0)
    header = _Ns(stamp=_Ns(sec=int(sec), nanosec=int(nsec)), frame_id=getattr(msg, "frame_id", ""))
    return _Wrapped(msg, header)


class _Wrapped:
    def __init__(self, msg, header):
        self._msg, self.header = msg, header

    def __getattr__(self, name):
        return getattr(self._msg, name)
