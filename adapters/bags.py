"""ROS bags and MCAP files (``bags`` adapter): ROS 1 ``.bag``, ROS 2 bag
directories (sqlite3 or MCAP storage), standalone ``.mcap`` (ROS 2 CDR, Foxglove
JSON or protobuf channels).

Which topic feeds which channel comes from a mapping (:mod:`.mapping`, a TOML
file or a dict); without one, :func:`.mapping.propose` picks the obvious one.
Messages become arrays by :mod:`.rosmsg`.

**One time axis.** ``t`` is the sorted union of the stamps of every mapped
topic (``header.stamp`` by default, the bag's log time with ``time = "log"``).
Each channel holds its topic's values at that topic's own stamps and is *not
valid* at every other sample (values NaN there): no sample is interpolated or
invented. Stamps shared by several topics are one sample. ``frame.report`` says
how many samples each topic fills. The other time of every message is kept as
the channel ``<name>_log_time`` (or ``<name>_header_time``), seconds on the
same origin as ``t``. ``meta["t0_ns"]`` is the absolute stamp of ``t = 0``.

**Simulation time.** Stamps before 1980 (``use_sim_time`` recordings, which
start near 0 s) give ``epoch = None`` and ``meta["sim_time"] = True``.

**Geodetic data.** NavSatFix positions are projected to the WGS 84 UTM zone of
the first mapped fix topic (median longitude) and expressed as local ENU
relative to its first valid fix: ``meta["crs"]``, ``meta["origin"]`` (easting,
northing) and ``meta["origin_alt"]``. Fixes with ``status < 0`` (NO_FIX) or
impossible coordinates are masked and counted.

**Bad input** raises :class:`~replay.util.errors.DataError` with one line naming the
file and topic: a missing topic, a topic of an unsupported or unexpected type,
no messages on a mapped topic, non-increasing stamps on a topic, a truncated or
corrupted file. After a truncation, the messages before it are used only with
``allow_truncated = true`` and the frame report then flags the recording as
truncated (``meta["truncated"]``).
"""
from __future__ import annotations

import difflib
import hashlib
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from replay.util.errors import DataError
from replay.frame import Channel, Frame, Report

from . import rosmsg
from .mapping import Mapping, from_dict, load_mapping, propose

SIM_TIME_BEFORE_NS = 315_532_800 * 10**9  # 1980-01-01: earlier stamps are simulation time


@dataclass
class Topic:
    name: str
    type: str
    count: int = 0
    log_ns: list = field(default_factory=list)
    msgs: list = field(default_factory=list)


@dataclass
class Recording:
    """What was read from a file: topics (with the requested messages) and format."""

    path: Path
    format: str
    topics: dict[str, Topic]
    start_ns: int | None
    end_ns: int | None
    truncated: str | None = None  # the reader's complaint, when reading stopped early
    read_messages: int = 0


# ---------------------------------------------------------------- reading

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
    kind = recording_kind(path)
    if kind == "ros2" and path.is_file():
        path = path.parent
    if kind == "mcap":
        return _read_mcap(path, topics, until, first_only)
    return _read_rosbags(path, kind, topics, until, first_only)


def _read_rosbags(path: Path, kind: str, topics, until, first_only=False) -> Recording:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    rec = Recording(path, kind, {}, None, None)
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as e:  # noqa: BLE001 - any reader failure is bad input here
        raise DataError(path, f"cannot open ({_reason(e)}); the file is truncated, corrupted "
                              "or not a bag; no message could be read") from None
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


def _reason(e: Exception) -> str:
    text = " ".join(str(e).split()) or type(e).__name__
    return text if len(text) < 160 else text[:157] + "..."


# ---------------------------------------------------------------- MCAP

def _read_mcap(path: Path, topics, until, first_only=False) -> Recording:
    """Stream every record (so a truncated file yields what precedes the damage)."""
    from mcap.stream_reader import StreamReader
    from mcap.records import Channel as McChannel, Message, Schema

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
            c.message_encoding == "cdr" for c in channels.values()):
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
            raise DataError(path, f"topic {ch.topic}: cannot decode a {topic.type} message "
                                  f"({_reason(e)})") from None
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
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    name = rosmsg.normalize_type(schema.name)
    if schema.data:
        store = get_typestore(Stores.EMPTY)
        try:
            store.register(get_types_from_msg(schema.data.decode(), name))
        except Exception as e:  # noqa: BLE001
            raise DataError(path, f"topic {channel.topic}: cannot parse the definition of {name} "
                                  f"({_reason(e)})") from None
    else:  # ROS 2 bags before Iron carry no definitions
        store = get_typestore(Stores.ROS2_HUMBLE)
        if name not in store.fielddefs:
            raise DataError(path, f"topic {channel.topic}: {name} has no definition in the file "
                                  "nor in the default (humble) typestore")
    return lambda data: store.deserialize_cdr(data, name)


def _protobuf_decoder(path, schema, channel):
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

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


# ---------------------------------------------------------------- geodesy

def utm_epsg(lat, lon) -> int:
    """EPSG code of the WGS 84 UTM zone (median longitude, latitude sign), as the CSV adapter."""
    zone = int(np.floor((np.median(lon) + 180.0) / 6.0)) % 60 + 1
    return (32600 if np.median(lat) >= 0 else 32700) + zone


class Geo:
    """lat/lon/alt <-> local ENU via the UTM zone of the first mapped fix topic."""

    def __init__(self, lat, lon, alt, ok):
        import pyproj

        self.epsg = utm_epsg(lat[ok], lon[ok])
        self._fwd = pyproj.Transformer.from_crs("EPSG:4326", f"EPSG:{self.epsg}", always_xy=True)
        first = int(np.argmax(ok))
        e, n = self._fwd.transform(lon[first], lat[first])
        self.origin = np.array([e, n, alt[first]], float)

    def forward(self, lat, lon, alt, ok):
        out = np.full((len(lat), 3), np.nan)
        if ok.any():
            e, n = self._fwd.transform(lon[ok], lat[ok])
            out[ok] = np.column_stack([e, n, alt[ok]]) - self.origin
        return out

    def meta(self) -> dict:
        return {"crs": f"EPSG:{self.epsg}", "epsg": self.epsg,
                "origin": [float(self.origin[0]), float(self.origin[1])],
                "origin_alt": float(self.origin[2])}


def enu_to_geodetic(enu, meta):
    """(n, 3) local ENU -> (lat, lon, alt) using ``meta`` crs / origin / origin_alt."""
    import pyproj

    inv = pyproj.Transformer.from_crs(meta["crs"], "EPSG:4326", always_xy=True)
    enu = np.asarray(enu, float)
    lon, lat = inv.transform(enu[:, 0] + meta["origin"][0], enu[:, 1] + meta["origin"][1])
    up = enu[:, 2] if enu.shape[1] > 2 else np.zeros(len(enu))
    return np.asarray(lat), np.asarray(lon), up + meta.get("origin_alt", 0.0)


# ---------------------------------------------------------------- the adapter

def resolve_mapping(mapping) -> Mapping | None:
    if mapping is None or isinstance(mapping, Mapping):
        return mapping
    if isinstance(mapping, dict):
        return from_dict(mapping)
    return load_mapping(mapping)


def load(path, *, mapping=None, time: str | None = None, until: float | None = None,
         allow_truncated: bool | None = None, **params) -> Frame:
    """Read a bag or MCAP into a Frame (see the module docstring).

    ``mapping``: a mapping file path, a dict of the same form, or None (proposed).
    ``time``, ``until``, ``allow_truncated`` and the conversion ``params``
    (water_density, atmospheric_pressure, gravity) override the mapping's.
    """
    path = Path(path).expanduser()
    mp = resolve_mapping(mapping)
    proposed = []

    def choose(listing):  # no mapping: propose one from the topic list
        proposed.append(propose(listing))
        if not proposed[0].entries:
            raise DataError(path, "no topic of a supported type to map; write a mapping "
                                  "(see `replay inspect` and docs/bags.md)")
        return proposed[0].topics

    until = until if until is not None else (mp.until if mp else None)
    rec = read(path, mp.topics if mp else choose, until)
    mp = mp or proposed[0]
    time = time or mp.time
    if time not in ("header", "log"):
        raise DataError(path, f"time must be 'header' or 'log' (got {time!r})")
    allow = mp.allow_truncated if allow_truncated is None else bool(allow_truncated)
    opts = {**mp.params, **params}
    report = Report()
    _fail_if_truncated(rec, report, allow)
    return build_frame(rec, mp, time, opts, report, until)


def _fail_if_truncated(rec: Recording, report, allow) -> None:
    if rec.truncated is None:
        return
    if not allow:
        raise DataError(rec.path, f"truncated or corrupted: {rec.truncated}; "
                                  f"{rec.read_messages} message(s) before it could be read — set "
                                  "allow_truncated = true in the mapping to use them (flagged)")
    if report is not None:
        report.add("flagged", str(rec.path), rec.read_messages,
                   f"TRUNCATED recording: only the messages before the damage were read ({rec.truncated})")


def _check_topics(rec: Recording, mp: Mapping) -> None:
    for e in mp.entries:
        topic = rec.topics.get(e.topic)
        if topic is None:
            close = difflib.get_close_matches(e.topic, list(rec.topics), n=1)
            hint = f" (did you mean {close[0]}?)" if close else f" (topics: {', '.join(rec.topics)})"
            raise DataError(rec.path, f"topic {e.topic} (mapped to {e.name}) is not in the recording{hint}")
        if rosmsg.kind_of(topic.type) is None:
            raise DataError(rec.path, f"topic {e.topic} has type {topic.type}, which no converter reads "
                                      f"(supported: {', '.join(sorted(rosmsg.KINDS))})")
        if e.type and rosmsg.normalize_type(e.type) != topic.type:
            raise DataError(rec.path, f"topic {e.topic}: the mapping expects {e.type}, the recording has {topic.type}")
        if not topic.msgs:
            span = " within `until`" if mp.until or rec.truncated else ""
            raise DataError(rec.path, f"topic {e.topic} (mapped to {e.name}) has no messages{span}")


def _stamps(rec: Recording, topic: Topic, time: str) -> tuple[np.ndarray, np.ndarray]:
    log = np.asarray(topic.log_ns, np.int64)
    header = np.array([rosmsg.stamp_ns(m) for m in topic.msgs], np.int64)
    use = header if time == "header" else log
    bad = np.flatnonzero(np.diff(use) <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        raise DataError(rec.path, f"topic {topic.name}: non-increasing {time} stamps at message {i} "
                                  f"({use[i]} ns after {use[i - 1]} ns)")
    return use, (log if time == "header" else header)


def build_frame(rec: Recording, mp: Mapping, time: str, opts: dict, report: Report,
                until: float | None) -> Frame:
    _check_topics(rec, mp)
    stamps, other, fields = {}, {}, {}
    geo = None
    for topic_name in mp.topics:
        topic = rec.topics[topic_name]
        stamps[topic_name], other[topic_name] = _stamps(rec, topic, time)
        kind = rosmsg.kind_of(topic.type)
        if kind == "navsatfix" and geo is None:
            geo = _make_geo(rec, topic)
        fields[topic_name] = rosmsg.convert(kind, topic.msgs, geo, opts)
    axis = np.unique(np.concatenate(list(stamps.values())))
    t0 = int(axis[0])
    t = (axis - t0) / 1e9
    n = len(axis)
    sim = t0 < SIM_TIME_BEFORE_NS
    channels, reference = {}, {}
    other_name = "header_time" if time == "log" else "log_time"
    for e in mp.entries:
        topic = rec.topics[e.topic]
        kind = rosmsg.kind_of(topic.type)
        idx = np.searchsorted(axis, stamps[e.topic])
        group = reference if e.reference else channels
        for fname, (vals, valid, unit, frame, comps, angles, conv) in fields[e.topic].items():
            key = e.name if fname == rosmsg.PRIMARY[kind] else f"{e.name}_{fname}"
            full = np.full((n,) + vals.shape[1:], np.nan)
            full[idx] = vals
            ok = np.zeros(n, bool)
            ok[idx] = valid
            group[key] = Channel(full, unit, frame, ok, tuple(comps), tuple(angles), conv,
                                 f"{e.topic} ({topic.type}) {fname}")
        t_other = np.full(n, np.nan)
        t_other[idx] = (other[e.topic] - t0) / 1e9
        group[f"{e.name}_{other_name}"] = Channel(t_other, "s", "", np.isin(np.arange(n), idx),
                                                  description=f"{e.topic} {other_name.replace('_', ' ')}, "
                                                              "seconds from t = 0")
        primary = fields[e.topic][rosmsg.PRIMARY[kind]][1]
        report.add("info", e.name, len(idx), f"{e.topic} ({topic.type}): {len(idx)} messages at their "
                                             f"{time} stamps; not valid at the other {n - len(idx)} samples")
        if (~primary).any():
            report.add("masked", e.name, int((~primary).sum()),
                       f"{e.topic}: messages with no usable value (e.g. NavSatFix status < 0 / NO_FIX, "
                       "NaN, unnormalised quaternion)")
    shared = sum(len(s) for s in stamps.values()) - n
    report.add("info", "t", n, f"union of the {time} stamps of {len(stamps)} mapped topic(s)"
                               + (f"; {shared} stamp(s) shared by several topics" if shared else ""))
    if sim:
        report.add("info", "t", n, f"simulation time: stamps start at {t0 / 1e9:.3f} s; epoch unknown")
    meta = {"adapter": "bags", "source": str(rec.path), "format": rec.format, "time": time,
            "t0_ns": t0, "sim_time": bool(sim), "until": until, "truncated": rec.truncated,
            "sha256": _sha256(rec.path), "mapping": json.loads(json.dumps(_mapping_dict(mp))),
            "topics": {k: {"type": v.type, "count": v.count, "read": len(v.msgs)}
                       for k, v in rec.topics.items()}}
    if geo is not None:
        meta.update(geo.meta())
    return Frame(t, channels, reference, None if sim else t0 / 1e9, meta, report)


def _make_geo(rec: Recording, topic: Topic) -> Geo:
    lat = np.array([m.latitude for m in topic.msgs], float)
    lon = np.array([m.longitude for m in topic.msgs], float)
    alt = np.array([m.altitude for m in topic.msgs], float)
    status = np.array([m.status.status if hasattr(m, "status") else 0 for m in topic.msgs])
    ok = (status >= 0) & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(alt) & \
        (np.abs(lat) <= 90) & (np.abs(lon) <= 180) & ~((lat == 0) & (lon == 0))
    if not ok.any():
        raise DataError(rec.path, f"topic {topic.name}: no valid fix (every status < 0 or lat/lon impossible)")
    return Geo(lat, lon, alt, ok)


def _mapping_dict(mp: Mapping) -> dict:
    return {"time": mp.time, "until": mp.until, "source": mp.source, "params": mp.params,
            "entries": [e.__dict__ for e in mp.entries]}


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    files = [path] if path.is_file() else sorted(p for p in path.iterdir() if p.is_file())
    for p in files:
        with open(p, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    return h.hexdigest()


# ---------------------------------------------------------------- inspect

def inspect(path) -> dict:
    """Topics (type, count, rate, span by log time), the recording span and a proposed mapping."""
    rec = read(path, None, first_only=True)
    rows = []
    for t in rec.topics.values():
        log = np.asarray(t.log_ns, np.int64)
        span = (log[-1] - log[0]) / 1e9 if len(log) > 1 else 0.0
        rate = (len(log) - 1) / span if span > 0 else float("nan")
        stamp0 = None
        if t.msgs and hasattr(t.msgs[0], "header"):
            stamp0 = rosmsg.stamp_ns(t.msgs[0]) / 1e9
        rows.append({"topic": t.name, "type": t.type, "count": t.count, "rate_hz": rate,
                     "span_s": span, "supported": rosmsg.kind_of(t.type) is not None,
                     "first_stamp_s": stamp0, "first_log_s": log[0] / 1e9 if len(log) else None})
    span = (rec.end_ns - rec.start_ns) / 1e9 if rec.start_ns is not None else 0.0
    mp = propose({t.name: (t.type, t.count) for t in rec.topics.values()})
    return {"path": str(rec.path), "format": rec.format, "start_ns": rec.start_ns, "span_s": span,
            "messages": sum(t.count for t in rec.topics.values()), "topics": rows,
            "truncated": rec.truncated, "mapping": mp}
