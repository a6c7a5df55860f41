"""Bulk MCAP writing: column-wise protobuf encoding decodes to the same messages,
BulkWriter files read back (Python mcap reader with CRCs, and mcap-validate when present),
and a file fed in time windows (flush) is the same byte for byte as one fed at once."""
import json

import numpy as np
import pytest
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from test_export_mcap import validate

from replay.util.errors import ReplayError
from replay.outputs.mcap_out import file_descriptor_set, json_rows
from replay.outputs.mcap_bulk import BulkWriter, gather
from replay.outputs.pb_columns import encode, varint


def test_varint_known_values():
    mat, lens = varint([0, 1, 127, 128, 300, 2**63 - 1, -1])
    got = [bytes(m[:k]) for m, k in zip(mat, lens)]
    assert got[:5] == [b"\x00", b"\x01", b"\x7f", b"\x80\x01", b"\xac\x02"]
    assert got[5] == b"\xff" * 8 + b"\x7f" and got[6] == b"\xff" * 9 + b"\x01"


def test_columns_decode_to_the_same_messages():
    rng = np.random.default_rng(3)
    n = 500
    ns = rng.integers(-2 * 10**9, 2 * 10**18, n)
    ns[:3] = [0, -1, 10**9]
    sec, nanos = np.divmod(ns, 1_000_000_000)
    xyz, q = rng.standard_normal((n, 3)) * 1e3, rng.standard_normal((n, 4))
    xyz[5], q[6] = 0.0, [0.0, -0.0, np.inf, np.nan]
    rows = encode(PoseInFrame, {"timestamp.seconds": sec, "timestamp.nanos": nanos, "frame_id": "enu",
                                **{f"pose.position.{a}": xyz[:, i] for i, a in enumerate("xyz")},
                                **{f"pose.orientation.{a}": q[:, i] for i, a in enumerate("xyzw")}}, n)
    buf, lens = rows.flat()
    assert lens.sum() == len(buf)
    for i, data in enumerate(rows.tobytes_list()):
        want = PoseInFrame(frame_id="enu")
        want.timestamp.seconds, want.timestamp.nanos = int(sec[i]), int(nanos[i])
        p, o = want.pose.position, want.pose.orientation
        p.x, p.y, p.z = xyz[i]
        o.x, o.y, o.z, o.w = q[i]
        got = PoseInFrame.FromString(data)
        assert got.SerializeToString(deterministic=True) == want.SerializeToString(deterministic=True), i
    fix = LocationFix.FromString(encode(LocationFix, {"latitude": 38.5, "longitude": -0.0, "altitude": 2.0,
                                                      "position_covariance_type": 2}, 1).tobytes_list()[0])
    assert (fix.latitude, fix.altitude, fix.position_covariance_type) == (38.5, 2.0, 2)
    with pytest.raises(KeyError, match="no field 'nope'"):
        encode(LocationFix, {"nope": 1.0}, 1)


def test_json_rows_exact_and_null():
    v = np.array([[0.1, -2e-300, 1e20], [np.nan, 1.0, np.inf], [1 / 3, 0.0, -5.5]])
    rows = [json.loads(r) for r in json_rows(v, ["a", "b%", 'c"'])]
    assert rows[0] == {"a": 0.1, "b%": -2e-300, 'c"': 1e20} and rows[2]["a"] == 1 / 3
    assert rows[1] == {"a": None, "b%": 1.0, 'c"': None}


def test_gather():
    buf = np.arange(20, dtype=np.uint8)
    assert gather(buf, [5, 0, 18], [2, 3, 2]).tolist() == [5, 6, 0, 1, 2, 18, 19]


@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
def test_bulk_writer_reads_back(tmp_path, compression):
    rng = np.random.default_rng(0)
    path = tmp_path / "b.mcap"
    w = BulkWriter(path, compression=compression, chunk_size=2000)
    sj = w.register_schema("replay.Values", "jsonschema", b'{"type": "object"}')
    sp = w.register_schema("foxglove.PoseInFrame", "protobuf", file_descriptor_set(PoseInFrame))
    want = []
    for k in range(3):  # JSON payloads of varying length, out-of-order times across channels
        cid = w.register_channel(f"/v{k}", "json", sj)
        t = np.sort(rng.integers(0, 10**9, 150 + k))
        data = [json.dumps({"x": float(x)}).encode() for x in rng.standard_normal(len(t))]
        w.add_messages(cid, t, data)
        want += [(int(ti), cid, d) for ti, d in zip(t, data)]
    cid = w.register_channel("/pose", "protobuf", sp)
    rows = encode(PoseInFrame, {"frame_id": "enu", "pose.position.x": np.arange(40.0)}, 40)
    t = np.full(40, 5 * 10**8)  # equal times keep their order
    w.add_messages(cid, t, rows.flat())
    want += [(int(ti), cid, d) for ti, d in zip(t, rows.tobytes_list())]
    assert w.finish() == len(want)
    want.sort(key=lambda r: r[0])  # stable: ties in registration, then message order
    with open(path, "rb") as fh:
        records = list(StreamReader(fh, validate_crcs=True).records)  # chunks broken up, CRCs checked
        assert sum(type(r).__name__ == "Message" for r in records) == len(want)
        fh.seek(0)
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary.statistics.message_count == len(want) and summary.statistics.chunk_count > 5
        assert summary.statistics.channel_message_counts[cid] == 40
        got = [(m.log_time, m.channel_id, m.data) for _, _, m in reader.iter_messages(log_time_order=True)]
    assert [g[0] for g in got] == [r[0] for r in want]
    assert sorted(got) == sorted(want)
    pose = [PoseInFrame.FromString(d).pose.position.x for _, c, d in got if c == cid]
    assert pose == list(np.arange(40.0))
    validate(path)


def test_bulk_writer_refuses_negative_times(tmp_path):
    w = BulkWriter(tmp_path / "n.mcap")
    cid = w.register_channel("/x", "json", w.register_schema("s", "jsonschema", b"{}"))
    with pytest.raises(ReplayError, match="topic /x: time -5 ns before 1970"):
        w.add_messages(cid, [-5, 0], [b"{}", b"{}"])


def test_bulk_writer_empty(tmp_path):
    w = BulkWriter(tmp_path / "e.mcap")
    w.register_channel("/x", "json", w.register_schema("s", "jsonschema", b"{}"))
    assert w.finish() == 0
    with open(tmp_path / "e.mcap", "rb") as fh:
        assert make_reader(fh).get_summary().statistics.message_count == 0
    validate(tmp_path / "e.mcap")


def _messages(rng):
    """Three channels of JSON payloads and one with a payload above mcap_bulk.BIG, times with ties."""
    chans = []
    for k in range(3):
        t = np.sort(rng.integers(0, 10**6, 400 + k)) // 1000 * 1000  # many equal times
        chans.append((t, [json.dumps({"x": float(x)}).encode() for x in rng.standard_normal(len(t))]))
    chans.append((np.array([5000, 700_000]), [b'{"s": "' + b"a" * (1 << 20) + b'"}', b"{}"]))
    return chans


def _write(path, chans, cuts, **kw):
    w = BulkWriter(path, chunk_size=2000, **kw)
    sj = w.register_schema("replay.Values", "jsonschema", b'{"type": "object"}')
    ids = [w.register_channel(f"/c{k}", "json", sj) for k in range(len(chans))]
    edges = [-1] + list(cuts) + [2**62]
    for lo, hi in zip(edges[:-1], edges[1:]):
        for cid, (t, data) in zip(ids, chans):
            sel = np.flatnonzero((t >= lo) & (t < hi))
            w.add_messages(cid, t[sel], [data[i] for i in sel])
        w.flush()
    return w.finish()


def test_bulk_writer_windows_give_the_same_bytes(tmp_path, monkeypatch):
    from replay.outputs import mcap_bulk

    chans = _messages(np.random.default_rng(1))
    n = _write(tmp_path / "whole.mcap", chans, [])
    monkeypatch.setattr(mcap_bulk, "BATCH", 300)  # records assembled 300 bytes at a time
    assert _write(tmp_path / "win.mcap", chans, [5000, 5001, 250_000, 600_000]) == n == 1205
    assert (tmp_path / "win.mcap").read_bytes() == (tmp_path / "whole.mcap").read_bytes()
    # file order: by time, ties by channel then message order
    want = sorted(((int(t), k, i, d) for k, (ts, data) in enumerate(chans) for i, (t, d) in enumerate(zip(ts, data))),
                  key=lambda r: r[:3])
    with open(tmp_path / "win.mcap", "rb") as fh:
        got = [(m.log_time, m.channel_id - 1, m.data)
               for _, _, m in make_reader(fh).iter_messages(log_time_order=False)]
    assert got == [(t, k, d) for t, k, _, d in want]
    validate(tmp_path / "win.mcap")


def test_bulk_writer_refuses_going_back_in_time(tmp_path):
    w = BulkWriter(tmp_path / "b.mcap")
    cid = w.register_channel("/x", "json", w.register_schema("s", "jsonschema", b"{}"))
    w.add_messages(cid, [10, 20], [b"{}", b"{}"])
    w.flush()
    w.add_messages(cid, [15], [b"{}"])
    with pytest.raises(ValueError, match="log time 15 before 20"):
        w.flush()
    with pytest.raises(ValueError, match="before the first flush"):
        w.register_channel("/y", "json", 1)
    w.close()


def test_bulk_writer_metadata_indexed(tmp_path):
    path = tmp_path / "m.mcap"
    w = BulkWriter(path)
    cid = w.register_channel("/x", "json", w.register_schema("s", "jsonschema", b"{}"), {"sigma": "3"})
    w.add_metadata("replay.manifest", {"manifest.json": '{"é": 1}\n'})
    w.add_messages(cid, [10, 20], [b"{}", b"{}"])
    assert w.finish() == 2
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        s = reader.get_summary()
        assert s.statistics.metadata_count == 1 and [m.name for m in s.metadata_indexes] == ["replay.manifest"]
        assert [(m.name, m.metadata) for m in reader.iter_metadata()] == [("replay.manifest",
                                                                          {"manifest.json": '{"é": 1}\n'})]
        assert s.channels[cid].metadata == {"sigma": "3"}
        fh.seek(0)
        kinds = [type(r).__name__ for r in StreamReader(fh, validate_crcs=True).records]
    assert kinds.index("Metadata") < kinds.index("Message") and "MetadataIndex" in kinds
    validate(path)
