"""Topic mapping files: which topic of a recording feeds which frame channel.

A mapping is a small TOML file (documented in ``docs/bags.md``)::

    time = "header"        # "header" (header.stamp, default) or "log" (the bag's receive time)
    until = 60.0           # optional: only messages logged within this many s of the first one
    allow_truncated = false  # optional: use what precedes a truncation (flagged in the report)

    [channels]             # sensor channels: name = topic, or name = {topic, type}
    gps = "/fix"
    odom = { topic = "/husky_velocity_controller/odom", type = "nav_msgs/msg/Odometry" }

    [reference]            # reference channels (truth / external reference), same form
    position = "/fix"

    [params]               # conversion parameters
    water_density = 1025.0
    atmospheric_pressure = 101325.0

Each entry ``name = topic`` gives the channel ``name`` (the message kind's primary
field, e.g. a position) and ``name_<field>`` for its other fields (see
:mod:`replay.adapters.rosmsg`).

**Roles.** A sensor entry also has a *role*: what a task may use it for,
whatever its name. By default the role follows the message type
(:data:`DEFAULT_ROLE`: NavSatFix -> ``gps``, Odometry -> ``odometry``, Imu ->
``imu``, FluidPressure -> ``depth``, Twist -> ``velocity``, Pose -> ``pose``);
``role = "..."`` in the entry declares another one that the type can supply
(:data:`ROLE_KINDS`, e.g. a DVL twist as ``odometry``, a pose as ``gps``), and
``role = "none"`` keeps a channel out of every task's inputs. Tasks find their
inputs by role (:func:`replay.tasks.role_input`), never by channel name.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from replay.util.errors import DataError, ReplayError

from .rosmsg import KINDS, kind_of, normalize_type

TOP_KEYS = {"time", "until", "allow_truncated", "channels", "reference", "params"}
PARAM_KEYS = {"water_density", "atmospheric_pressure", "gravity"}
ENTRY_KEYS = {"topic", "type", "role"}

# role -> the message kinds (rosmsg.KINDS) that can supply it
ROLE_KINDS = {
    "gps": ("navsatfix", "pose"),  # position fixes
    "odometry": ("odometry", "twist"),  # forward speed and yaw rate in the vehicle frame
    "imu": ("imu",),  # body angular rates (gyro)
    "depth": ("pressure",),
    "velocity": ("twist", "odometry"),
    "pose": ("pose", "odometry"),
    "none": ("navsatfix", "odometry", "imu", "pressure", "twist", "pose"),
}
DEFAULT_ROLE = {"navsatfix": "gps", "odometry": "odometry", "imu": "imu", "pressure": "depth",
                "twist": "velocity", "pose": "pose"}


@dataclass
class Entry:
    name: str
    topic: str
    type: str | None = None  # expected message type (checked when given)
    reference: bool = False
    role: str | None = None  # declared role (None: from the message type, DEFAULT_ROLE)


@dataclass
class Mapping:
    entries: list[Entry] = field(default_factory=list)
    time: str = "header"
    until: float | None = None
    allow_truncated: bool = False
    params: dict = field(default_factory=dict)
    source: str = "(proposed)"

    @property
    def topics(self) -> list[str]:
        return list(dict.fromkeys(e.topic for e in self.entries))

    def to_toml(self) -> str:
        lines = [f'time = "{self.time}"']
        if self.until is not None:
            lines.append(f"until = {self.until!r}")
        for group, ref in (("channels", False), ("reference", True)):
            lines += ["", f"[{group}]"]
            for e in self.entries:
                if e.reference == ref:
                    typ = f', type = "{e.type}"' if e.type else ""
                    role = f', role = "{e.role}"' if e.role else ""
                    lines.append(f'{e.name} = {{ topic = "{e.topic}"{typ}{role} }}')
        if self.params:
            lines += ["", "[params]"] + [f"{k} = {v!r}" for k, v in self.params.items()]
        return "\n".join(lines) + "\n"


def load_mapping(path) -> Mapping:
    """Read and check a mapping file; errors name the file and the key."""
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(path, "no such mapping file") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise DataError(path, f"cannot read mapping: {e}") from None
    return from_dict(doc, str(path))


def from_dict(doc: dict, source: str = "(mapping)") -> Mapping:
    unknown = sorted(set(doc) - TOP_KEYS)
    if unknown:
        raise ReplayError(f"{source}: unknown key(s) {', '.join(unknown)} (known: {', '.join(sorted(TOP_KEYS))})")
    time = doc.get("time", "header")
    if time not in ("header", "log"):
        raise ReplayError(f"{source}: time must be \"header\" or \"log\" (got {time!r})")
    until = doc.get("until")
    if until is not None and (isinstance(until, bool) or not isinstance(until, (int, float))
                              or not until > 0 or until == float("inf")):
        raise ReplayError(f"{source}: until must be a positive number of seconds (got {until!r})")
    allow = doc.get("allow_truncated", False)
    if not isinstance(allow, bool):
        raise ReplayError(f"{source}: allow_truncated must be true or false (got {allow!r})")
    params = doc.get("params", {})
    if not isinstance(params, dict):
        raise ReplayError(f"{source}: [params] must be a table of name = number")
    params = dict(params)
    bad = sorted(set(params) - PARAM_KEYS)
    if bad:
        raise ReplayError(f"{source}: unknown param(s) {', '.join(bad)} (known: {', '.join(sorted(PARAM_KEYS))})")
    for key, value in params.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < float("inf"):
            raise ReplayError(f"{source}: [params] {key} must be a positive finite number (got {value!r})")
    entries = []
    for group, ref in (("channels", False), ("reference", True)):
        table = doc.get(group, {})
        if not isinstance(table, dict):
            raise ReplayError(f"{source}: [{group}] must be a table of name = topic")
        for name, spec in table.items():
            if isinstance(spec, str):
                spec = {"topic": spec}
            if not isinstance(spec, dict) or not isinstance(spec.get("topic"), str) or not spec["topic"]:
                raise ReplayError(f"{source}: [{group}] {name}: give a topic (name = \"/topic\")")
            extra = sorted(set(spec) - ENTRY_KEYS)
            if extra:
                raise ReplayError(f"{source}: [{group}] {name}: unknown key(s) {', '.join(extra)} "
                                  f"(known: {', '.join(sorted(ENTRY_KEYS))})")
            typ = spec.get("type")
            if typ is not None and (not isinstance(typ, str) or kind_of(typ) is None):
                raise ReplayError(f"{source}: [{group}] {name}: unknown message type {typ!r} "
                                  f"(supported: {', '.join(sorted(KINDS))})")
            role = spec.get("role")
            if role is not None and ref:
                raise ReplayError(f"{source}: [reference] {name}: a reference has no role "
                                  "(roles are for [channels] entries)")
            if role is not None and role not in ROLE_KINDS:
                raise ReplayError(f"{source}: [channels] {name}: unknown role {role!r} "
                                  f"(known: {', '.join(ROLE_KINDS)})")
            if role is not None and typ is not None and kind_of(typ) not in ROLE_KINDS[role]:
                raise ReplayError(f"{source}: [channels] {name}: a {normalize_type(typ)} cannot have role "
                                  f"{role!r} (it takes {kinds_for(role)})")
            entries.append(Entry(name, spec["topic"], normalize_type(typ) if typ else None, ref, role))
    if not entries:
        raise ReplayError(f"{source}: maps no topic ([channels] and [reference] are empty)")
    return Mapping(entries, time, float(until) if until is not None else None, allow, params, source)


def kinds_for(role: str) -> str:
    """The message types that can have ``role``, in words (for error messages)."""
    return ", ".join(t.split("/")[-1] for t, k in KINDS.items() if k in ROLE_KINDS[role]
                     and not t.startswith("foxglove"))


def role_of(entry: Entry, msgtype: str, source: str) -> str | None:
    """The role of a sensor entry whose topic has type ``msgtype`` (None for a reference).

    A declared role the type cannot supply is refused (one line naming the mapping,
    the entry and the type).
    """
    if entry.reference:
        return None
    kind = kind_of(msgtype)
    if entry.role is None:
        return DEFAULT_ROLE.get(kind)
    if kind not in ROLE_KINDS[entry.role]:
        raise ReplayError(f"{source}: [channels] {entry.name}: topic {entry.topic} is a {msgtype}, which "
                          f"cannot have role {entry.role!r} (it takes {kinds_for(entry.role)})")
    return entry.role


def propose(topics: dict[str, tuple[str, int]]) -> Mapping:
    """A mapping for the obvious cases, from ``{topic: (type, count)}``.

    Each supported topic becomes a channel named after its kind (gps, odom, imu,
    depth, dvl, pose; numbered when a kind repeats). The reference is a pose or
    odometry topic named like ground truth (``truth``, ``groundtruth``,
    ``ground_truth``, ``gt``, ``reference``, ``mocap``, ``vicon``); failing
    that, a single NavSatFix (the fix track as reference, see docs/bags.md).
    """
    names = {"navsatfix": "gps", "odometry": "odom", "imu": "imu", "pressure": "depth",
             "twist": "dvl", "pose": "pose"}
    entries, used = [], {}
    truth_words = ("groundtruth", "ground_truth", "truth", "gt", "reference", "mocap", "vicon")
    reference = None
    for topic, (typ, count) in topics.items():
        kind = kind_of(typ)
        if kind is None or count == 0:
            continue
        base = topic.strip("/").lower().replace("/", "_")
        if reference is None and kind in ("pose", "odometry") and any(
                w == base or base.endswith(w) or base.startswith(w) for w in truth_words):
            reference = Entry("position", topic, normalize_type(typ), True)
            continue
        stem = names[kind]
        used[stem] = used.get(stem, 0) + 1
        name = stem if used[stem] == 1 else f"{stem}{used[stem]}"
        entries.append(Entry(name, topic, normalize_type(typ)))
    if reference is None:
        fixes = [e for e in entries if e.type and kind_of(e.type) == "navsatfix"]
        if len(fixes) == 1:
            reference = Entry("position", fixes[0].topic, fixes[0].type, True)
    if reference is not None:
        entries.append(reference)
    return Mapping(entries)
