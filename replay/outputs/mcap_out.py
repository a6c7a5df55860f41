"""The MCAP writer of the exports: protobuf schemas (:func:`file_descriptor_set`), channels and
messages encoded in time windows (:class:`McapOut`), JSON rows (:func:`json_rows`)."""

from __future__ import annotations

import json

import numpy as np

from replay.util.errors import ReplayError
from google.protobuf.descriptor_pb2 import FileDescriptorProto, FileDescriptorSet
from replay.outputs.mcap_bulk import BulkWriter


def file_descriptor_set(message_class) -> bytes:
    """The FileDescriptorSet of a generated protobuf class and all its dependencies."""
    fds, seen, todo = FileDescriptorSet(), set(), [message_class.DESCRIPTOR.file]
    while todo:
        fd = todo.pop()
        if fd.name in seen:
            continue
        seen.add(fd.name)
        todo.extend(fd.dependencies)
        proto = FileDescriptorProto()
        fd.CopyToProto(proto)
        fds.file.insert(0, proto)  # dependencies before the files that use them
    return fds.SerializeToString()


class McapOut:
    """Protobuf and JSON channels by topic, written in time windows by ``mcap_bulk.BulkWriter``.

    Each channel is declared with the log times of all its messages and a function
    ``encode(sel)`` giving the payloads of the messages ``sel`` (an index array); the
    file is then written window by window (:meth:`close`), each window about
    ``window`` messages of all channels between two times, so that only one window's
    payloads exist at a time. The order (time, then channel declaration, then message)
    and so the file are the same as if every channel were encoded at once.
    """

    def __init__(self, path, compression: str = "zstd", chunk_size: int = 4 << 20, window: int = 1 << 16, name=None):
        self.w = BulkWriter(path, compression=compression, chunk_size=chunk_size, name=name)
        self.schemas, self.channels, self.count, self.window = {}, {}, 0, window
        self.plans: list[tuple] = []  # (channel id, sorted times, message order, encode)

    def proto_channel(self, topic, message_class, metadata=None) -> int:
        name = message_class.DESCRIPTOR.full_name
        if name not in self.schemas:
            self.schemas[name] = self.w.register_schema(name, "protobuf", file_descriptor_set(message_class))
        return self._channel(topic, self.schemas[name], "protobuf", metadata)

    def json_channel(self, topic, properties: list[str]) -> int:
        key = "json:" + ",".join(properties)
        if key not in self.schemas:
            schema = {"type": "object", "properties": {p: {"type": "number"} for p in properties}}
            self.schemas[key] = self.w.register_schema("replay.Values", "jsonschema", json.dumps(schema).encode())
        return self._channel(topic, self.schemas[key], "json")

    def _channel(self, topic, schema_id, encoding, metadata=None) -> int:
        if topic in self.channels:
            raise ReplayError(f"export: topic {topic} written twice")
        self.channels[topic] = self.w.register_channel(topic, encoding, schema_id, metadata)
        return self.channels[topic]

    def plan(self, channel_id, t_ns, encode, big: bool = False) -> None:
        """Messages of one channel: their times (ns) and ``encode(sel) -> payloads`` of messages ``sel``.

        ``big``: a few large messages (a whole path); each is written alone, so that
        only one of them is in memory at a time.
        """
        t = np.asarray(t_ns, np.int64)
        order = np.argsort(t, kind="stable") if np.any(t[1:] < t[:-1]) else None  # None: in order
        self.plans.append((channel_id, t if order is None else t[order], order, encode, big))

    def _bounds(self) -> np.ndarray:
        """Times that cut the messages into windows of about ``self.window`` messages."""
        times = [p[1] for p in self.plans if len(p[1])]
        total = sum(map(len, times))
        # the instant of each big message is a window of its own: [t, t + 1)
        cuts = [np.r_[t, t + 1] for _, t, _, _, big in self.plans if big]
        if total > self.window:
            step = max(1, self.window // (8 * len(times)))
            cand = np.unique(np.concatenate([t[::step] for t in times]))
            before = sum(np.searchsorted(t, cand, "left") for t in times)  # messages earlier than each
            j = np.searchsorted(before, np.arange(self.window, total, self.window), "left")
            cuts.append(cand[j[j < len(cand)]])
        return np.unique(np.concatenate(cuts)) if cuts else np.zeros(0, np.int64)

    def close(self, progress=None) -> int:
        """Write every planned message, window by window, and finish the file; returns the count.

        ``progress``: a :class:`replay.util.progress.Progress` told of the messages written; it
        reaches its total only once the file is finished (a failure to finish leaves it short)."""
        bounds = self._bounds()
        edges = [np.r_[0, np.searchsorted(p[1], bounds, "left"), len(p[1])] for p in self.plans]
        total = sum(len(p[1]) for p in self.plans)
        told = 0
        if progress is not None:
            progress.start(total)
        try:
            for k in range(len(bounds) + 1):
                # one instant: its messages keep the channel order when flushed channel by channel
                instant = 0 < k < len(bounds) and bounds[k] == bounds[k - 1] + 1
                for (cid, t, order, encode, _), e in zip(self.plans, edges):
                    a, b = e[k], e[k + 1]
                    if b > a:
                        sel = np.arange(a, b) if order is None else order[a:b]
                        self.count += self.w.add_messages(cid, t[a:b], encode(sel))
                        if progress is not None and self.count < total:
                            progress.update(self.count - told)
                            told = self.count
                        if instant:
                            self.w.flush()
                self.w.flush()
            self.w.finish()
        finally:
            self.w.close()
        if progress is not None:
            progress.update(self.count - told)
        return self.count


def json_rows(values, names) -> list[bytes]:
    """One JSON object ``{name: value}`` per row; exact floats (repr), non-finite values as null."""
    values = np.asarray(values, float)
    fmt = "{" + ",".join(json.dumps(n).replace("%", "%%") + ":%r" for n in names) + "}"
    finite = np.isfinite(values).all(axis=1)
    good = values[finite]
    text = ("\n".join([fmt] * len(good)) % tuple(good.ravel().tolist())).encode().split(b"\n") if len(good) else []
    if finite.all():
        return text
    rows, it = [], iter(text)
    keys = [json.dumps(n) + ":" for n in names]
    for ok_row, row in zip(finite.tolist(), values.tolist()):
        rows.append(
            next(it)
            if ok_row
            else ("{" + ",".join(k + (repr(x) if np.isfinite(x) else "null") for k, x in zip(keys, row)) + "}").encode()
        )
    return rows
