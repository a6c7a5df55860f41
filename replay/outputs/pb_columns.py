"""Protobuf encoding of many messages at once, column by column, with numpy.

``encode(Cls, {"pose.position.x": array, ..., "frame_id": "enu"}, n)`` gives the wire
bytes of ``n`` messages of the generated class ``Cls`` whose named (dotted) fields take
the given per-row values, in one pass of array operations instead of ``n`` calls to
``SerializeToString``. Field numbers and types come from ``Cls.DESCRIPTOR`` (the
published schema itself; nothing is copied by hand).

Each row is kept as byte segments: a ``uint8`` matrix ``(n, width)`` and the used
length per row (varints vary in length); ``Rows.flat()`` packs them with one boolean
mask into the concatenated message bytes and their lengths.

Wire format (protobuf encoding spec): tag = varint(number << 3 | wire type); wire type
0 varint, 1 fixed 64-bit, 2 length-delimited, 5 fixed 32-bit. Every field that is named
is written, including values equal to the default (0.0): a parser reads the same
message, which is only a few bytes longer than the canonical (default-omitting) form.
Negative integers are written as 10-byte two's complement varints, as protobuf does for
int32/int64.
"""

from __future__ import annotations

import numpy as np
from google.protobuf.descriptor import FieldDescriptor as FD

_VARINT_TYPES = {FD.TYPE_INT32, FD.TYPE_INT64, FD.TYPE_UINT32, FD.TYPE_UINT64, FD.TYPE_BOOL, FD.TYPE_ENUM}
_FIXED = {
    FD.TYPE_DOUBLE: "<f8",
    FD.TYPE_FLOAT: "<f4",
    FD.TYPE_FIXED64: "<u8",
    FD.TYPE_SFIXED64: "<i8",
    FD.TYPE_FIXED32: "<u4",
    FD.TYPE_SFIXED32: "<i4",
}


class Rows:
    """``n`` byte strings as a list of segments ``(matrix (n, w) uint8, lengths (n,))``."""

    def __init__(self, n: int, segments=()):
        self.n, self.segments = n, list(segments)

    def lengths(self) -> np.ndarray:
        total = np.zeros(self.n, np.int64)
        for _, lens in self.segments:
            total += lens
        return total

    def flat(self) -> tuple[np.ndarray, np.ndarray]:
        """(all rows' bytes concatenated as uint8, length of each row)."""
        if not self.segments:
            return np.zeros(0, np.uint8), np.zeros(self.n, np.int64)
        mat = np.concatenate([m for m, _ in self.segments], axis=1)
        mask = np.concatenate([np.arange(m.shape[1]) < lens[:, None] for m, lens in self.segments], axis=1)
        return mat[mask], self.lengths()

    def tobytes_list(self) -> list[bytes]:
        buf, lens = self.flat()
        data, ends = buf.tobytes(), np.cumsum(lens).tolist()
        return [data[a:b] for a, b in zip([0] + ends[:-1], ends)]


def const(n: int, data: bytes) -> tuple:
    b = np.frombuffer(data, np.uint8)
    return np.broadcast_to(b, (n, len(b))), np.full(n, len(b), np.int64)


def varint(values) -> tuple:
    """Base-128 varints of integers (negative ones as 64-bit two's complement)."""
    u = np.asarray(values).astype(np.int64).view(np.uint64)
    lens = np.ones(len(u), np.int64)
    for k in range(1, 10):
        lens += (u >> np.uint64(7 * k)) > 0
    shifts = np.arange(10, dtype=np.uint64) * np.uint64(7)
    mat = ((u[:, None] >> shifts) & np.uint64(0x7F)).astype(np.uint8)
    mat |= np.where(np.arange(10) < (lens - 1)[:, None], 0x80, 0).astype(np.uint8)
    return mat, lens


def _uvarint(key: int) -> bytes:
    out = bytearray()
    while True:
        out.append(key & 0x7F | (0x80 if key > 0x7F else 0))
        key >>= 7
        if not key:
            return bytes(out)


def _tag(number: int, wire: int) -> bytes:
    return _uvarint(number << 3 | wire)


def _field(fd, value, n: int) -> list:
    if fd.type == FD.TYPE_MESSAGE:
        if not isinstance(value, dict):
            raise TypeError(f"field {fd.full_name}: a message needs sub-fields")
        return embed(fd.number, encode_descriptor(fd.message_type, value, n))
    if fd.type in (FD.TYPE_STRING, FD.TYPE_BYTES):
        data = value.encode() if isinstance(value, str) else bytes(value)
        return [const(n, _tag(fd.number, 2) + _uvarint(len(data)) + data)]
    if fd.type in _VARINT_TYPES:
        return [const(n, _tag(fd.number, 0)), varint(np.broadcast_to(value, (n,)))]
    if fd.type in _FIXED:
        dt = np.dtype(_FIXED[fd.type])
        col = np.ascontiguousarray(np.broadcast_to(np.asarray(value, dt), (n,)))
        wire = 1 if dt.itemsize == 8 else 5
        return [
            const(n, _tag(fd.number, wire)),
            (col.view(np.uint8).reshape(n, dt.itemsize), np.full(n, dt.itemsize, np.int64)),
        ]
    raise TypeError(f"field {fd.full_name}: type {fd.type} not supported by pb_columns")


def embed(number: int, rows: Rows) -> list:
    """Segments of a length-delimited field ``number`` holding each row of ``rows``."""
    return [const(rows.n, _tag(number, 2)), varint(rows.lengths())] + rows.segments


def encode_descriptor(desc, values: dict, n: int) -> Rows:
    groups: dict = {}
    for path, v in values.items():
        head, _, rest = path.partition(".")
        if rest:
            groups.setdefault(head, {})[rest] = v
        else:
            groups[head] = v
    rows = Rows(n)
    for name, v in groups.items():
        fd = desc.fields_by_name.get(name)
        if fd is None:
            raise KeyError(f"{desc.full_name} has no field {name!r}")
        rows.segments += _field(fd, v, n)
    return rows


def encode(message_class, values: dict, n: int) -> Rows:
    """``n`` messages of ``message_class`` with dotted-path field values (arrays of n or scalars)."""
    return encode_descriptor(message_class.DESCRIPTOR, values, n)
