"""A chunked, indexed MCAP writer for whole channels at once.

``mcap.writer.Writer`` spends about 15-20 µs of Python per ``add_message`` (a record
object, a stream write per field, an index tuple). An export writes every channel's
messages from arrays, so this writer takes a channel's messages in one call
(``add_messages(channel, log_times, payload)``) and lays out the file with numpy:

- the message records of all channels, ordered by log time (stable: registration
  order breaks ties), are gathered into chunks of about ``chunk_size`` uncompressed
  bytes; each chunk is followed by its Message Index records (per channel: log time
  and offset of every message in the chunk);
- Header, Schema, Channel, Chunk, Chunk Index, Data End, Statistics, Summary Offset
  and Footer records are written with the ``mcap`` library's own record classes
  (``mcap.records``), laid out as ``mcap.writer.Writer.finish`` does (schemas and
  channels repeated in the summary, CRCs of chunks, data section and summary).

Record layout (MCAP specification, "Message" op 0x05): opcode u8, record length u64,
channel id u16, sequence u32, log time u64, publish time u64, data. Publish time =
log time; sequence 0, as in the export's previous writer.
"""
from __future__ import annotations

import struct
import zlib

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Schema, Statistics,
                          SummaryOffset)
from mcap.writer import MCAP0_MAGIC

from replay.util.errors import ReplayError

_MSG_HEADER = np.dtype([("op", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                        ("log_time", "<u8"), ("publish_time", "<u8")])  # 31 bytes, packed


def gather(buf: np.ndarray, starts: np.ndarray, lens: np.ndarray) -> np.ndarray:
    """Concatenate the byte ranges ``buf[starts[i] : starts[i] + lens[i]]`` in order."""
    lens = np.asarray(lens, np.int64)
    if not len(lens):
        return np.zeros(0, np.uint8)
    before = np.cumsum(lens) - lens
    return buf[np.repeat(np.asarray(starts, np.int64) - before, lens) + np.arange(int(lens.sum()))]


def payload_of(data) -> tuple[np.ndarray, np.ndarray]:
    """``(bytes as uint8, lengths)`` from a list of bytes or an already flat pair."""
    if isinstance(data, tuple):
        return np.asarray(data[0], np.uint8), np.asarray(data[1], np.int64)
    lens = np.fromiter(map(len, data), np.int64, len(data))
    return np.frombuffer(b"".join(data), np.uint8), lens


class BulkWriter:
    """Collect channels' messages as arrays, write the whole MCAP file on ``finish``."""

    def __init__(self, path, compression: str = "zstd", chunk_size: int = 4 << 20, library: str = "replay"):
        if compression not in ("zstd", "lz4", ""):
            raise ValueError(f"compression {compression!r}: one of zstd, lz4, ''")
        self.path, self.compression, self.chunk_size, self.library = path, compression, chunk_size, library
        self.schemas: list[Schema] = []
        self.channels: list[Channel] = []
        self.parts: list[tuple] = []  # (channel id, log times, payload bytes, payload lengths)

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        self.schemas.append(Schema(id=len(self.schemas) + 1, data=data, encoding=encoding, name=name))
        return self.schemas[-1].id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata=None) -> int:
        self.channels.append(Channel(id=len(self.channels) + 1, topic=topic, message_encoding=message_encoding,
                                     metadata=dict(metadata or {}), schema_id=schema_id))
        return self.channels[-1].id

    def add_messages(self, channel_id: int, log_times, data) -> int:
        """Messages of one channel: ``log_times`` (ns, int) and payloads (list of bytes or (uint8, lengths))."""
        t = np.asarray(log_times, np.int64).reshape(-1)
        buf, lens = payload_of(data)
        if len(lens) != len(t):
            raise ValueError(f"channel {channel_id}: {len(t)} times for {len(lens)} payloads")
        if len(t) and t.min() < 0:
            topic = self.channels[channel_id - 1].topic
            raise ReplayError(f"{self.path}: topic {topic}: time {t.min()} ns before 1970 (MCAP log times are unsigned)")
        if len(t):
            self.parts.append((channel_id, t, buf, lens))
        return len(t)

    # ---------------------------------------------------------------- layout

    def _records(self):
        """All message records in log-time order: (bytes, record starts, channel ids, log times)."""
        ch = np.concatenate([np.full(len(p[1]), p[0], np.uint16) for p in self.parts])
        t = np.concatenate([p[1] for p in self.parts])
        lens = np.concatenate([p[3] for p in self.parts])
        payload = np.concatenate([p[2] for p in self.parts])
        order = np.argsort(t, kind="stable")
        n = len(t)
        hdr = np.zeros(n, _MSG_HEADER)
        hdr["op"], hdr["length"], hdr["channel"] = int(Opcode.MESSAGE), 22 + lens, ch
        hdr["log_time"] = hdr["publish_time"] = t.view(np.uint64)
        # one source buffer: payloads, then the 31-byte headers; each record = header + payload
        src = np.concatenate([payload, hdr.view(np.uint8)])
        p_start = np.cumsum(lens) - lens
        h_start = len(payload) + np.arange(n, dtype=np.int64) * _MSG_HEADER.itemsize
        starts = np.column_stack([h_start[order], p_start[order]]).ravel()
        sizes = np.column_stack([np.full(n, _MSG_HEADER.itemsize), lens[order]]).ravel()
        rec_len = _MSG_HEADER.itemsize + lens[order]
        return gather(src, starts, sizes), np.cumsum(rec_len) - rec_len, ch[order], t[order]

    def _compress(self, data: bytes) -> bytes:
        if self.compression == "zstd":
            import zstandard
            return zstandard.ZstdCompressor(level=1).compress(data)
        if self.compression == "lz4":
            import lz4.frame
            return lz4.frame.compress(data)
        return data

    def finish(self) -> int:
        """Write the file; returns the number of messages."""
        out, rb = bytearray(MCAP0_MAGIC), RecordBuilder()
        Header(profile="", library=self.library).write(rb)
        for s in self.schemas:
            s.write(rb)
        for c in self.channels:
            c.write(rb)
        out += rb.end()
        chunk_indexes, counts, n = [], {}, 0
        t_min = t_max = 0
        if self.parts:
            body, starts, ch, t = self._records()
            n, t_min, t_max = len(t), int(t.min()), int(t.max())
            bounds = np.flatnonzero(np.diff(starts // self.chunk_size)) + 1
            for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, n]):
                end = starts[hi] if hi < n else len(body)
                self._chunk(out, rb, body[starts[lo]:end].tobytes(), starts[lo:hi] - starts[lo], ch[lo:hi],
                            t[lo:hi], chunk_indexes)
            ids, cnt = np.unique(ch, return_counts=True)
            counts = dict(zip(ids.tolist(), cnt.tolist()))
        DataEnd(data_section_crc=zlib.crc32(out)).write(rb)
        out += rb.end()
        self._summary(out, chunk_indexes, counts, n, t_min, t_max)
        with open(self.path, "wb") as fh:
            fh.write(out)
        return n

    def _chunk(self, out, rb, data: bytes, offsets, ch, t, chunk_indexes) -> None:
        compressed = self._compress(data)
        chunk = Chunk(compression=self.compression, data=compressed, message_start_time=int(t.min()),
                      message_end_time=int(t.max()), uncompressed_crc=zlib.crc32(data), uncompressed_size=len(data))
        chunk.write(rb)
        chunk_start = len(out)
        out += rb.end()
        index_start, index_offsets = len(out), {}
        for cid in np.unique(ch).tolist():
            sel = ch == cid
            pairs = np.column_stack([t[sel].view(np.uint64), offsets[sel].astype(np.uint64)]).astype("<u8")
            index_offsets[cid] = len(out)
            out += struct.pack("<BQHI", int(Opcode.MESSAGE_INDEX), 6 + pairs.nbytes, cid, pairs.nbytes)
            out += pairs.tobytes()
        chunk_indexes.append(ChunkIndex(
            message_start_time=chunk.message_start_time, message_end_time=chunk.message_end_time,
            chunk_start_offset=chunk_start, chunk_length=index_start - chunk_start,
            message_index_offsets=index_offsets, message_index_length=len(out) - index_start,
            compression=self.compression, compressed_size=len(compressed), uncompressed_size=len(data)))

    def _summary(self, out, chunk_indexes, counts, n, t_min, t_max) -> None:
        summary_start, sb, offsets = len(out), RecordBuilder(), []
        groups = [(Opcode.SCHEMA, self.schemas), (Opcode.CHANNEL, self.channels),
                  (Opcode.STATISTICS, [Statistics(
                      message_count=n, schema_count=len(self.schemas), channel_count=len(self.channels),
                      attachment_count=0, metadata_count=0, chunk_count=len(chunk_indexes),
                      message_start_time=t_min, message_end_time=t_max, channel_message_counts=counts)]),
                  (Opcode.CHUNK_INDEX, chunk_indexes)]
        for opcode, records in groups:
            if not records:
                continue
            start = sb.count
            for r in records:
                r.write(sb)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + start,
                                         group_length=sb.count - start))
        offset_start = summary_start + sb.count
        for o in offsets:
            o.write(sb)
        summary = sb.end()
        crc = zlib.crc32(struct.pack("<BQQQ", int(Opcode.FOOTER), 20, summary_start, offset_start),
                         zlib.crc32(summary))
        out += summary
        Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc).write(sb)
        out += sb.end() + MCAP0_MAGIC
