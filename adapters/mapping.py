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
(:func:`replay.roles.default_role`: NavSatFix -> ``gps``, Odometry -> ``odometry``, Imu ->
``imu``, FluidPressure -> ``depth``, Twist -> ``velocity``, Pose -> ``pose``);
``role = "..."`` in the entry declares another one that the type can supply
(``replay.roles.ROLES``, e.g. a DVL twist as ``odometry``, a pose as ``gps``), and
``role = "none"`` keeps a channel out of every task's inputs. Tasks find their
inputs by role (:func:`replay.tasks.role_input`), never by channel name.

**Recorded estimates.** ``[estimates]`` names what an estimator already
recorded (``name = "/topic"`` or ``name = {topic, type, frame, child,
t_max_diff, t_offset, align}``): Odometry, PoseStamped, PoseWithCovarianceStamped,
a TF pair (TFMessage / TransformStamped with ``frame`` = parent and ``child``),
nav_msgs/Path (its last message) or NavSatFix. They become
``Frame.estimates`` (leaderboard rows ``recorded:<name>``), never a filter's
input; ``t_max_diff`` / ``t_offset`` (s) are the defaults of their time
association with the reference, ``align`` (none, yaw, se3, sim3) of the fit that
first moves them onto the reference (replay.trajectory.recorded.RECORDED_PARAMS).
``frame``/``child`` also select a TF pair in ``[channels]`` and ``[reference]`` (a TF-only recording needs them).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import tomli_w

from replay import roles
from replay.util import tomlfile, tomlschema
from replay.util.errors import ReplayError, shown
from replay.util.params import Param
from replay.util.tomlschema import Each, Table, Value

from .mapping_fields import frame_declarations
from .rosmsg import KINDS, kind_of, normalize_type


ESTIMATE_ALIGN = ("none", "yaw", "se3", "sim3")  # replay.scoring.align.ALIGNMENTS
_POSITIVE = dict(low=0.0, low_open=True, optional=True)
_PAIR = (
    Param("topic", str, None, "the topic (name = \"/topic\" says it alone)"),
    Value("type", (str,), "the expected message type (checked when given)"),
    Value("frame", (str,), "a TF pair's parent frame (with child)"),
    Value("child", (str,), "a TF pair's child frame (with frame)"),
)
CHANNEL = Table(  # a [channels] (or [reference]) entry; a reference refuses the fusion keys (_fusion)
    "channels",
    "[channels] {name}",
    (
        *_PAIR,
        Value("role", (str,), "what a task may use it for (replay.roles.ROLES; none: no task)"),
        Value("fuse", (list,), "the fields fused (the fusion task)", str, "a list of field names"),
        Value("differential", (list,), "the fields fused as differences", str, "a list of field names"),
        Value("noise", (dict,), "field = variance (the field's unit squared)", None, "a table of field = variance"),
        Value(
            "rejection_threshold", (float, int, dict), "Mahalanobis", None, "a number or a table of field = threshold"
        ),
        Value("twist_frame", (str,), "an Odometry's twist frame: child or parent"),
        Value("mount", (list,), "an IMU's rotation in the body frame, [roll, pitch, yaw] rad"),
        Value("lever_arm", (list,), "a GPS antenna's position in the body frame, [x, y, z] m"),
    ),
    required=("topic",),
    shorthand="topic",
)
REFERENCE = Table("reference", "[reference] {name}", CHANNEL.keys, ("topic",), shorthand="topic")
ESTIMATE = Table(
    "estimates",
    "[estimates] {name}",
    (
        *_PAIR,
        Param("t_max_diff", float, None, "s: the largest time difference associated", low=0.0, optional=True),
        Param("t_offset", float, None, "s: added to the estimate's times", optional=True),
        Param("align", str, None, "the fit onto the reference", choices=ESTIMATE_ALIGN, optional=True),
    ),
    required=("topic",),
    shorthand="topic",
)
PARAMS = Table(
    "params",
    "[params]",
    (
        Param("water_density", float, None, "kg/m^3 (a depth from a pressure)", **_POSITIVE),
        Param("atmospheric_pressure", float, None, "Pa (a depth from a pressure)", **_POSITIVE),
        Param("gravity", float, None, "m/s^2 (a depth from a pressure)", **_POSITIVE),
    ),
)
MAPPING = Table(  # the one declaration of a mapping file (the checks it cannot state: from_dict)
    "mapping",
    "",
    (
        Param("time", str, "header", "header (header.stamp) or log (the receive time)", choices=("header", "log")),
        Param("until", float, None, "s: only messages logged within this long of the first one", **_POSITIVE),
        Param("allow_truncated", bool, False, "use what precedes a truncation (flagged in the report)"),
        Each("channels", CHANNEL, doc="sensor channels: name = topic or name = {topic, ...}"),
        Each("reference", REFERENCE, doc="reference channels, same form"),
        Each("estimates", ESTIMATE, doc="recorded estimates scored as rows recorded:<name>"),
        PARAMS,
    ),
)
ESTIMATE_KINDS = ("odometry", "pose", "navsatfix", "tf", "path")  # what a recorded estimate may be
ESTIMATE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}")  # it names a row and a file (fullmatch)
CHANNEL_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}")  # a frame channel and a topic token /sensors/<name>


@dataclass
class Entry:
    name: str
    topic: str
    type: str | None = None  # expected message type (checked when given)
    reference: bool = False
    role: str | None = None  # declared role (None: from the message type, replay.roles.default_role)
    frame: str | None = None  # TF pair: parent frame (TFMessage / TransformStamped topics)
    child: str | None = None  # TF pair: child frame
    estimate: bool = False  # an [estimates] entry
    params: dict = field(default_factory=dict)  # [estimates]: t_max_diff, t_offset
    fusion: dict = field(default_factory=dict)  # [channels]: fuse, differential, noise (the fusion task)

    @property
    def group(self) -> str:
        return "estimates" if self.estimate else "reference" if self.reference else "channels"

    @property
    def pair(self) -> str:
        return f" [{self.frame} -> {self.child}]" if self.frame or self.child else ""


@dataclass
class Mapping:
    entries: list[Entry] = field(default_factory=list)
    time: str = "header"
    until: float | None = None
    allow_truncated: bool = False
    params: dict = field(default_factory=dict)
    source: str = "(proposed)"
    estimates: list[Entry] = field(default_factory=list)

    @property
    def topics(self) -> list[str]:
        return list(dict.fromkeys(e.topic for e in self.entries + self.estimates))

    def to_toml(self) -> str:
        """The mapping file (``load_mapping`` reads it back to this mapping), written by tomli-w."""
        doc: dict = {"time": self.time}
        if self.until is not None:
            doc["until"] = self.until
        if self.allow_truncated:
            doc["allow_truncated"] = True
        for group in ("channels", "reference", "estimates"):
            chosen = [e for e in self.entries + self.estimates if e.group == group]
            if group == "estimates" and not chosen:
                continue
            doc[group] = {e.name: _entry_doc(e) for e in chosen}
        if self.params:
            doc["params"] = dict(self.params)
        return tomli_w.dumps(doc)


def _entry_doc(e: Entry) -> dict:
    """An entry's table: its topic, the declarations it has, its estimate and fusion keys."""
    pairs = (("type", e.type), ("role", e.role), ("frame", e.frame), ("child", e.child))
    return {"topic": e.topic, **{k: v for k, v in pairs if v}, **e.params, **e.fusion}


def load_mapping(path) -> Mapping:
    """Read and check a mapping file; errors name the file and the key."""
    path = Path(path)
    doc, _ = tomlfile.load(path, "a mapping")
    return from_dict(doc, str(path))


def from_dict(doc: dict, source: str = "(mapping)") -> Mapping:
    tomlschema.check(MAPPING, doc, lambda key, text: ReplayError(f"{source}: {text}"))
    time, until = doc.get("time", "header"), doc.get("until")
    allow, params = doc.get("allow_truncated", False), dict(doc.get("params", {}))
    entries, estimates = [], []
    for group, ref in (("channels", False), ("reference", True), ("estimates", False)):
        for name, spec in doc.get(group, {}).items():
            if group == "estimates":
                _estimate_name(source, name)  # before it is quoted in any other message
            elif not CHANNEL_NAME.fullmatch(name):
                raise ReplayError(
                    f"{source}: [{group}] {shown(name)}: a channel name is a letter, then letters, "
                    "digits and _ (at most 64; it names the frame channel and the exported topic "
                    "/sensors/<name>)"
                )
            if isinstance(spec, str):
                spec = {"topic": spec}
            if not spec["topic"]:
                raise ReplayError(f"{source}: [{group}] {name}: give a topic (name = \"/topic\")")
            typ = spec.get("type")
            if typ is not None and kind_of(typ) is None:
                raise ReplayError(
                    f"{source}: [{group}] {name}: unknown message type {shown(typ)} "
                    f"(supported: {', '.join(sorted(KINDS))})"
                )
            frame, child = _pair(source, group, name, spec)
            if group == "estimates":
                estimates.append(_estimate(source, name, spec, typ, frame, child))
                continue
            role = spec.get("role")
            if role is not None and ref:
                raise ReplayError(
                    f"{source}: [reference] {name}: a reference has no role (roles are for [channels] entries)"
                )
            if role is not None and role not in roles.names():
                raise ReplayError(
                    f"{source}: [channels] {name}: unknown role {shown(role)} (known: {', '.join(roles.names())})"
                )
            if role is not None and typ is not None and pose_like(kind_of(typ)) not in roles.kinds_of(role):
                raise ReplayError(
                    f"{source}: [channels] {name}: a {normalize_type(typ)} cannot have role "
                    f"{shown(role)} (it takes {kinds_for(role)})"
                )
            fusion = _fusion(source, name, spec, ref)
            entries.append(
                Entry(name, spec["topic"], normalize_type(typ) if typ else None, ref, role, frame, child, fusion=fusion)
            )
    if not entries:
        raise ReplayError(
            f"{source}: maps no topic ([channels] and [reference] are empty)"
            + ("; recorded [estimates] need a [reference] to be scored against" if estimates else "")
        )
    return Mapping(entries, time, float(until) if until is not None else None, allow, params, source, estimates)


def _fusion(source: str, name: str, spec: dict, ref: bool) -> dict:
    """The fusion task's settings of a [channels] entry: ``fuse`` and ``differential`` (lists of
    fields), ``noise`` (a table field = variance, in the field's unit squared),
    ``rejection_threshold`` (a Mahalanobis distance: one number for every field, or a table
    field = distance; robot_localization's ``*_rejection_threshold``)."""
    out = frame_declarations(spec, f"{source}: [{'reference' if ref else 'channels'}] {name}", ref)
    for key in ("fuse", "differential", "noise", "rejection_threshold"):
        if key not in spec:
            continue
        if ref:
            raise ReplayError(f"{source}: [reference] {name}: {key} is for [channels] entries (the fusion task)")
        value = spec[key]
        if key == "rejection_threshold" and not isinstance(value, dict):  # one threshold for every field
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < float("inf"):
                raise ReplayError(
                    f"{source}: [channels] {name}: rejection_threshold must be a positive Mahalanobis "
                    f"distance (got {value!r})"
                )
            out[key] = float(value)
            continue
        fields = list(value)  # a list of names or a table (their types: CHANNEL's declaration)
        bad = [f for f in fields if f not in roles.known_fields()]
        if bad:
            raise ReplayError(
                f"{source}: [channels] {name}: {key}: unknown field {shown(bad[0])} "
                f"(fields: {', '.join(roles.known_fields())})"
            )
        if key == "noise":
            for f, v in value.items():
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < float("inf"):
                    raise ReplayError(
                        f"{source}: [channels] {name}: noise.{f} must be a positive variance (got {shown(v)})"
                    )
            value = {f: float(v) for f, v in value.items()}
        if key == "rejection_threshold":
            for f, v in value.items():
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < float("inf"):
                    raise ReplayError(
                        f"{source}: [channels] {name}: rejection_threshold.{f} must be a positive "
                        f"Mahalanobis distance (got {v!r})"
                    )
            value = {f: float(v) for f, v in value.items()}
        out[key] = value
    roles.check_field_lists(out.get("fuse"), out.get("differential"), f"{source}: [channels] {name}")
    return out


def _pair(source: str, group: str, name: str, spec: dict):
    """The TF pair (``frame`` = parent, ``child``) an entry selects, or (None, None)."""
    frame, child = spec.get("frame"), spec.get("child")
    for key, value in (("frame", frame), ("child", child)):
        if value is not None and (not isinstance(value, str) or not value.strip("/")):
            raise ReplayError(f"{source}: [{group}] {name}: {key} must be a frame name (got {shown(value)})")
    if (frame is None) != (child is None):
        raise ReplayError(f"{source}: [{group}] {name}: a TF pair needs both frame (the parent) and child")
    return (frame.strip("/"), child.strip("/")) if frame is not None else (None, None)


def _estimate(source: str, name: str, spec: dict, typ, frame, child) -> Entry:
    """One ``[estimates]`` entry, checked (message kind, association defaults; its name by
    :func:`_estimate_name`)."""
    if typ is not None and kind_of(typ) not in ESTIMATE_KINDS:
        raise ReplayError(
            f"{source}: [estimates] {name}: a {normalize_type(typ)} is not a trajectory "
            "(an estimate is an Odometry, PoseStamped, PoseWithCovarianceStamped, TFMessage / "
            "TransformStamped pair, Path or NavSatFix)"
        )
    params = {k: ESTIMATE.known()[k].check(spec[k]) for k in ("t_max_diff", "t_offset", "align") if k in spec}
    return Entry(name, spec["topic"], normalize_type(typ) if typ else None, False, None, frame, child, True, params)


def _estimate_name(source: str, name: str) -> None:
    if not ESTIMATE_NAME.fullmatch(name) or name == "none":
        raise ReplayError(
            f"{source}: [estimates] {shown(name)}: a name of letters, digits and _ . + - (at most 64, "
            "starting with a letter or digit, not 'none'; it names the leaderboard row "
            "recorded:<name> and its files)"
        )


def pose_like(kind: str | None) -> str | None:
    """The kind whose converter reads a message kind: a TF pair and a Path are poses."""
    return "pose" if kind in ("tf", "path") else kind


def kinds_for(role: str) -> str:
    """The message types that can have ``role``, in words (for error messages)."""
    return ", ".join(
        t.split("/")[-1] for t, k in KINDS.items() if k in roles.kinds_of(role) and not t.startswith("foxglove")
    )


def role_of(entry: Entry, msgtype: str, source: str) -> str | None:
    """The role of a sensor entry whose topic has type ``msgtype`` (None for a reference).

    A declared role the type cannot supply is refused (one line naming the mapping,
    the entry and the type).
    """
    if entry.reference:
        return None
    kind = pose_like(kind_of(msgtype))
    if entry.role is None:
        return roles.default_role(kind)
    if kind not in roles.kinds_of(entry.role):
        raise ReplayError(
            f"{source}: [channels] {entry.name}: topic {entry.topic} is a {msgtype}, which "
            f"cannot have role {shown(entry.role)} (it takes {kinds_for(entry.role)})"
        )
    return entry.role
