"""Export an evaluation (``replay eval`` output directory) as one Foxglove MCAP.

Reads ``manifest.json`` and ``estimates/<filter>.csv.gz`` (run 0: the first
Monte Carlo run), reloads the dataset named in the manifest (same adapter,
mapping, ``first`` and, for a simulator, the run-0 seed) and rebuilds the task
problem for the reference. No filter is run again.

Channels (schemas from the ``foxglove-schemas-protobuf`` package; log time =
publish time = the sample's time, ``meta["t0_ns"]`` or ``epoch`` + ``t``):

| topic | schema | what |
|---|---|---|
| ``/replay/<filter>/pose`` | foxglove.PoseInFrame | estimated position (and heading when the task scores one), every step |
| ``/replay/<filter>/path`` | foxglove.PosesInFrame | the whole estimated trajectory, one message at the first time |
| ``/replay/<filter>/fix`` | foxglove.LocationFix | the estimate in WGS 84 (geodetic data only: meta crs + origin) |
| ``/replay/<filter>/error`` | JSON ``{ex, ey[, ez], norm}`` | position error vs the reference (m), scored steps |
| ``/replay/reference/pose``, ``/path``, ``/fix`` | as above | the reference where valid |
| ``/sensors/<channel>`` | JSON ``{<component>: value}`` | every sensor channel of the frame at its valid samples |

Frame id of poses and paths: ``"enu"`` (the local east-north-up frame).

Each channel is encoded at once (``replay.outputs.pb_columns`` for protobuf, ``json_rows``
for JSON) and written by ``replay.outputs.mcap_bulk.BulkWriter`` (time-ordered zstd chunks).
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

from replay.util.errors import DataError, ReplayError

FRAME_ID = "enu"


# ---------------------------------------------------------------- reading a run

def load_run(run_dir, data_dir=None) -> dict:
    """The manifest, run-0 estimates per filter, the frame and the rebuilt problem."""
    from replay import registry
    from replay.pipeline import resolve
    from replay.util.seeds import rng_for
    from replay.tasks import make_task

    run_dir = Path(run_dir)
    try:
        man = json.loads((run_dir / "manifest.json").read_text())
        cfg = man["config"]
    except FileNotFoundError:
        raise DataError(run_dir / "manifest.json", "no such file: not a `replay eval` output directory") from None
    except (ValueError, KeyError) as e:
        raise DataError(run_dir / "manifest.json", f"not a replay manifest ({e})") from None
    ds = resolve(cfg["dataset"])
    frame = registry.load_frame(cfg["dataset"], data_dir=data_dir, rng=rng_for(cfg["seed"], 0, 0),
                                first=cfg.get("first"), adapter=cfg.get("adapter"),
                                **(cfg.get("dataset_params") or {}))
    task = make_task(cfg["task"], **(cfg.get("task_params") or {}))
    if ds is not None and ds.kind == "sim":
        pass  # the generator was seeded as in run 0 above
    problem = task.build(frame, rng_for(cfg["seed"], 0, 1))
    estimates = {}
    for name in cfg["filters"]:
        estimates[name] = read_estimates(run_dir / "estimates" / f"{name}.csv.gz")
    return {"config": cfg, "frame": frame, "problem": problem, "estimates": estimates}


def read_estimates(path, run: int = 0) -> dict:
    """``{t, x, err}`` of one run from an ``estimates/<filter>.csv.gz`` file."""
    try:
        with gzip.open(path, "rt") as fh:
            head = fh.readline().strip().split(",")
            data = np.loadtxt(fh, delimiter=",", ndmin=2)
    except FileNotFoundError:
        raise DataError(path, "no such estimates file") from None
    except (OSError, ValueError, EOFError) as e:
        raise DataError(path, f"cannot read estimates ({e})") from None
    nx = sum(1 for h in head if h.startswith("x") and h[1:].isdigit())
    data = data[data[:, 0] == run]
    n_err = data.shape[1] - 3 - 2 * nx
    return {"t": data[:, 2], "x": data[:, 3:3 + nx], "P": data[:, 3 + nx:3 + 2 * nx],
            "err": data[:, 3 + 2 * nx:3 + 2 * nx + n_err]}


# ---------------------------------------------------------------- schemas

def file_descriptor_set(message_class) -> bytes:
    """The FileDescriptorSet of a generated protobuf class and all its dependencies."""
    from google.protobuf.descriptor_pb2 import FileDescriptorProto, FileDescriptorSet

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
    """Protobuf and JSON channels by topic over ``replay.outputs.mcap_bulk.BulkWriter`` (whole channels at once)."""

    def __init__(self, path, compression: str = "zstd"):
        from replay.outputs.mcap_bulk import BulkWriter

        self.w = BulkWriter(path, compression=compression)
        self.schemas, self.channels, self.count = {}, {}, 0

    def proto_channel(self, topic, message_class) -> int:
        name = message_class.DESCRIPTOR.full_name
        if name not in self.schemas:
            self.schemas[name] = self.w.register_schema(name, "protobuf", file_descriptor_set(message_class))
        return self._channel(topic, self.schemas[name], "protobuf")

    def json_channel(self, topic, properties: list[str]) -> int:
        key = "json:" + ",".join(properties)
        if key not in self.schemas:
            schema = {"type": "object", "properties": {p: {"type": "number"} for p in properties}}
            self.schemas[key] = self.w.register_schema("replay.Values", "jsonschema", json.dumps(schema).encode())
        return self._channel(topic, self.schemas[key], "json")

    def _channel(self, topic, schema_id, encoding) -> int:
        if topic in self.channels:
            raise ReplayError(f"export: topic {topic} written twice")
        self.channels[topic] = self.w.register_channel(topic, encoding, schema_id)
        return self.channels[topic]

    def add_many(self, channel_id, t_ns, data) -> None:
        """Messages of one channel: times (ns) and payloads (list of bytes or ``Rows.flat()``)."""
        self.count += self.w.add_messages(channel_id, t_ns, data)

    def close(self):
        self.w.finish()


# ---------------------------------------------------------------- writing

def time_ns(frame, t) -> np.ndarray:
    """Absolute nanoseconds of frame times ``t``: meta t0_ns, else epoch, else 0, plus t."""
    t0 = frame.meta.get("t0_ns")
    if t0 is None:
        t0 = int(round(frame.epoch * 1e9)) if frame.epoch is not None else 0
    return int(t0) + np.round(np.asarray(t, float) * 1e9).astype(np.int64)


def _quat_yaw(yaw):
    return np.column_stack([np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2), np.cos(yaw / 2)])


def _stamp(ns) -> dict:
    sec, nanos = np.divmod(np.asarray(ns, np.int64), 1_000_000_000)
    return {"timestamp.seconds": sec, "timestamp.nanos": nanos}


def _pose_fields(pos3, quat, prefix="") -> dict:
    f = {f"{prefix}position.{a}": pos3[:, i] for i, a in enumerate("xyz")}
    f.update({f"{prefix}orientation.{a}": quat[:, i] for i, a in enumerate("xyzw")})
    return f


def _write_track(out: McapOut, prefix: str, ns, pos, yaw, ok, geo_meta) -> None:
    from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
    from foxglove_schemas_protobuf.Pose_pb2 import Pose
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
    from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame

    from replay.outputs.pb_columns import embed, encode

    idx = np.flatnonzero(ok)
    if not len(idx):
        return
    n, t = len(idx), ns[idx]
    pos3 = pos if pos.shape[1] == 3 else np.column_stack([pos, np.zeros(len(pos))])
    pos3 = pos3[idx]
    quat = _quat_yaw(np.where(np.isfinite(yaw), yaw, 0.0))[idx]
    poses = encode(PoseInFrame, {**_stamp(t), "frame_id": FRAME_ID, **_pose_fields(pos3, quat, "pose.")}, n)
    out.add_many(out.proto_channel(f"{prefix}/pose", PoseInFrame), t, poses.flat())
    # the whole path: one PosesInFrame whose repeated `poses` field is every pose in turn
    head = encode(PosesInFrame, {**_stamp(t[:1]), "frame_id": FRAME_ID}, 1).flat()[0]
    items = encode(Pose, _pose_fields(pos3, quat), n)
    number = PosesInFrame.DESCRIPTOR.fields_by_name["poses"].number
    body = type(items)(n, embed(number, items)).flat()[0]
    path = np.concatenate([head, body])
    out.add_many(out.proto_channel(f"{prefix}/path", PosesInFrame), t[:1], (path, [len(path)]))
    if geo_meta:
        from replay.adapters.geodesy import enu_to_geodetic

        lat, lon, alt = enu_to_geodetic(pos3, geo_meta)
        fixes = encode(LocationFix, {**_stamp(t), "frame_id": FRAME_ID, "latitude": lat, "longitude": lon,
                                     "altitude": alt}, n)
        out.add_many(out.proto_channel(f"{prefix}/fix", LocationFix), t, fixes.flat())


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
        rows.append(next(it) if ok_row else ("{" + ",".join(
            k + (repr(x) if np.isfinite(x) else "null") for k, x in zip(keys, row)) + "}").encode())
    return rows


def _write_values(out: McapOut, topic, ns, values, ok, names) -> None:
    idx = np.flatnonzero(ok)
    if not len(idx):
        return
    cid = out.json_channel(topic, names)
    out.add_many(cid, ns[idx], json_rows(values.reshape(len(values), -1)[idx], names))


def _heading_index(problem):
    for name in ("heading", "yaw", "psi"):
        if name in problem.angle_index:
            return problem.angle_index[name]
    model = problem.model
    angles = getattr(model, "x_angles", ())
    return angles[0] if len(angles) == 1 else None


def export_run(run_dir, mcap_path, data_dir=None) -> int:
    """Write the run in ``run_dir`` as a Foxglove MCAP; returns the number of messages."""
    run = load_run(run_dir, data_dir)
    return write_mcap(mcap_path, run["frame"], run["problem"], run["estimates"])


def write_mcap(mcap_path, frame, problem, estimates: dict) -> int:
    """Estimates ``{filter: {t, x, err}}`` of one run, the reference and the sensors -> MCAP."""
    geo = frame.meta if frame.meta.get("crs") and frame.meta.get("origin") else None
    ns_frame = time_ns(frame, frame.t)
    pidx = list(problem.position_index)
    hidx = _heading_index(problem)
    out = McapOut(mcap_path)  # nothing is written before close(): a failure leaves no partial file
    ref = np.asarray(problem.truth_position, float)
    ok = problem.truth_valid & np.isfinite(ref).all(axis=1)
    _write_track(out, "/replay/reference", ns_frame, ref, np.full(len(ref), np.nan), ok, geo)
    axes = [f"e{a}" for a in problem.axis_names]
    for name, est in estimates.items():
        ns = time_ns(frame, est["t"])
        x = est["x"]
        pos = x[:, pidx]
        yaw = x[:, hidx] if hidx is not None else np.full(len(x), np.nan)
        _write_track(out, f"/replay/{name}", ns, pos, yaw, np.isfinite(pos).all(axis=1), geo)
        err = est["err"][:, :len(pidx)]
        ok_e = np.isfinite(err).all(axis=1)
        vals = np.column_stack([err, np.sqrt(np.sum(np.where(ok_e[:, None], err, 0.0) ** 2, axis=1))])
        _write_values(out, f"/replay/{name}/error", ns, vals, ok_e, axes + ["norm"])
    for cname, ch in frame.channels.items():
        comps = list(ch.components) or ([cname] if ch.width == 1 else [f"c{i}" for i in range(ch.width)])
        _write_values(out, f"/sensors/{cname}", ns_frame, ch.values, ch.valid, comps)
    out.close()
    return out.count
