"""Sensor roles: one record per kind of sensor input, read by the adapters and the tasks.

A *role* says what a task may use a sensor for, whatever its channels are called: which
message kinds can supply it, which of their fields it lists, which fields the ``fusion`` task
fuses by default, which state components each field measures (with a sign and an angle flag),
where a field's noise comes from, and the frame conventions of its messages. It is one
:class:`Role` entry of :data:`ROLES`; a field it measures is a :class:`Field` (the shared ones
in :data:`FIELDS`, or the role's own). Adding a sensor (a barometer, a magnetometer heading,
a DVL) is one ``ROLES`` entry plus, when its message kind is new, its converter
(:mod:`replay.adapters.rosmsg`): docs/architecture.md, "Add a sensor role".

An adapter lists the inputs it found as :class:`SensorInput` records on ``Frame.roles``
(a bag: one per mapped ``[channels]`` entry, its role declared or the message kind's
default; bohai-csv: the columns it checked). ``Frame.roles`` is None for frames whose adapter
declares no roles (the simulators: tasks fall back to channels named after the role).
:func:`as_meta` is their form in a manifest (``dataset.roles``: role -> list of entries).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

from replay.util.errors import ReplayError, shown


class Component(NamedTuple):
    """One measured state component of a field: the channel's column, the state index it
    measures, the sign (depth = -up) and whether it is an angle (wrapped innovations)."""

    column: int
    state: int
    sign: float = 1.0
    angle: bool = False


def _c(*rows) -> tuple[Component, ...]:
    return tuple(Component(*r) for r in rows)


@dataclass(frozen=True)
class Field:
    """A measured field of a message (a channel ``<entry>_<name>``, or the entry's primary one).

    ``planar``/``spatial``: its components in the 2-D state ``[east, north, yaw, u, v, r]`` and
    the 3-D state ``[east, north, up, roll, pitch, yaw, u, v, w, p, q, r]``
    (:mod:`replay.models.kinematic`). ``noise``: the fusion task's parameter of its default
    variance (``r_*``), used where neither a declared ``noise`` nor a recorded covariance (the
    ``<entry>_<name>_var`` channel) gives one. ``differential``: the field its deltas measure
    (pose deltas: a body velocity, body rates), None when it is only absolute. ``axes``: how a
    sensor's mounting rotation acts on it (``vector``: a vector in the sensor's axes,
    ``attitude``: the sensor's orientation), None when it does not. ``twist``: a twist field
    (an Odometry's, in its child frame by REP 105, or declared ``twist_frame``)."""

    name: str
    planar: tuple[Component, ...]
    spatial: tuple[Component, ...]
    noise: str
    differential: str | None = None
    axes: str | None = None
    twist: bool = False

    def components(self, dims: int) -> tuple[Component, ...]:
        return self.planar if dims == 2 else self.spatial


FIELDS = {
    f.name: f
    for f in (
        Field("position", _c((0, 0), (1, 1)), _c((0, 0), (1, 1), (2, 2)), "r_position", differential="velocity"),
        Field(
            "attitude",
            _c((2, 2, 1.0, True)),
            _c(*((i, 3 + i, 1.0, True) for i in range(3))),
            "r_attitude",
            differential="rate",
            axes="attitude",
        ),
        Field("velocity", _c((0, 3), (1, 4)), _c(*((i, 6 + i) for i in range(3))), "r_velocity", twist=True),
        Field("rate", _c((2, 5)), _c(*((i, 9 + i) for i in range(3))), "r_rate", twist=True),
        Field("gyro", _c((2, 5)), _c(*((i, 9 + i) for i in range(3))), "r_rate", axes="vector"),
        Field("depth", (), _c((0, 2, -1.0)), "r_depth"),
    )
}


@dataclass(frozen=True)
class Role:
    """One kind of sensor input (see the module docstring).

    ``kinds``: the message kinds (:data:`replay.adapters.rosmsg.KINDS` values) that can supply
    it; ``default_for``: those whose role it is when the mapping declares none. ``fields``: the
    message fields its input lists (``SensorInput.channels``). ``fuse``: what the fusion task
    fuses by default (robot_localization's per-sensor ``*_config`` for it); ``fuse_beside_fixes``:
    the default instead where an absolute position input exists (None: the same). ``own``: fields
    defined for this role only, or redefining a shared one (a GPS fix has no usable height in a
    3-D state). ``mount``: how the sensor's mounting in the body frame (a declared ``mount`` or
    the recording's static transform base -> sensor frame) acts on it: ``rotation`` (its vectors
    and orientation are rotated into the body axes), ``lever_arm`` (its position is the
    antenna's: moved to the body origin where the heading is known), None. ``holdout``: when its
    position topic is also the reference, only every ``gps_every``-th fix is fed, the others are
    held out for scoring. ``recorded_covariance``: a message's own covariance is its default
    noise (per message, bad entries replaced and counted)."""

    name: str
    kinds: tuple[str, ...]
    fields: tuple[str, ...]
    fuse: tuple[str, ...]
    default_for: tuple[str, ...] = ()
    fuse_beside_fixes: tuple[str, ...] | None = None
    own: tuple[Field, ...] = ()
    mount: str | None = None
    holdout: bool = False
    recorded_covariance: bool = True
    doc: str = ""

    def field(self, name: str) -> Field:
        """The field ``name`` as this role measures it (its own definition first)."""
        for f in self.own:
            if f.name == name:
                return f
        if name not in FIELDS:
            raise KeyError(name)
        return FIELDS[name]

    def components(self, name: str, dims: int) -> tuple[Component, ...]:
        return self.field(name).components(dims)


ROLES = {
    r.name: r
    for r in (
        Role(
            "gps",
            ("navsatfix", "pose"),
            ("position",),
            ("position",),
            default_for=("navsatfix",),
            own=(Field("position", _c((0, 0), (1, 1)), _c((0, 0), (1, 1)), "r_position", differential="velocity"),),
            mount="lever_arm",
            holdout=True,
            doc="position fixes (east, north; a fix's height is not fused)",
        ),
        Role(
            "odometry",
            ("odometry", "twist"),
            ("velocity", "rate"),
            ("velocity", "rate"),
            default_for=("odometry",),
            doc="forward speed and yaw rate in the vehicle frame",
        ),
        Role(
            "imu",
            ("imu",),
            ("gyro", "accel", "attitude"),
            ("gyro", "attitude"),
            default_for=("imu",),
            fuse_beside_fixes=("gyro",),
            mount="rotation",
            doc="body angular rates (gyro) and orientation; its yaw is fused by default only without "
            "absolute positions (it is in the IMU's own world frame unless checked east-north-up)",
        ),
        Role("depth", ("pressure",), ("depth",), ("depth",), default_for=("pressure",), doc="depth, positive down"),
        Role(
            "velocity",
            ("twist", "odometry"),
            ("velocity",),
            ("velocity",),
            default_for=("twist",),
            doc="body velocity (a DVL)",
        ),
        Role(
            "pose",
            ("pose", "odometry"),
            ("position", "attitude"),
            ("position", "attitude"),
            default_for=("pose",),
            doc="absolute position and attitude",
        ),
    )
}
NONE = "none"  # a declared role that keeps a channel out of every task's inputs


def get(name: str) -> Role:
    """The role ``name`` (KeyError when unknown)."""
    return ROLES[name]


def kinds_of(name: str) -> tuple[str, ...]:
    """The message kinds that can have role ``name`` (every kind of any role for ``none``)."""
    if name == NONE:
        return tuple(dict.fromkeys(k for r in ROLES.values() for k in r.kinds))
    return ROLES[name].kinds


def names() -> tuple[str, ...]:
    """Every role a mapping may declare, in order (``none`` last)."""
    return (*ROLES, NONE)


def default_role(kind: str | None) -> str | None:
    """The role of a message kind when none is declared (None: the kind has none)."""
    return next((r.name for r in ROLES.values() if kind in r.default_for), None)


def known_fields() -> tuple[str, ...]:
    """Every field a ``fuse``/``differential``/``noise`` entry may name."""
    return tuple(dict.fromkeys([*FIELDS, *(f.name for r in ROLES.values() for f in r.own)]))


def differential_fields() -> tuple[str, ...]:
    """The fields that may be fused as deltas (pose fields)."""
    every = [*FIELDS.values(), *(f for r in ROLES.values() for f in r.own)]
    return tuple(dict.fromkeys(f.name for f in every if f.differential))


def check_field_lists(fuse, differential, where: str) -> None:
    """An entry's declared ``fuse`` and ``differential`` lists (None: not declared) mean one thing:
    not empty, no field twice, only pose fields differential, no field both absolute and differential."""
    for key, fields in (("fuse", fuse), ("differential", differential)):
        if fields is not None and not fields:
            raise ReplayError(
                f"{where}: {key} = [] names no field: leave it out ("
                + (
                    'the role\'s default), or set role = "none" to keep the channel out of every task'
                    if key == "fuse"
                    else "no field is differential by default)"
                )
            )
        fields = list(fields or ())
        twice = next((f for i, f in enumerate(fields) if f in fields[:i]), None)
        if twice is not None:
            raise ReplayError(f"{where}: {key} names {shown(twice)} twice (a field is fused once)")
    bad = [f for f in differential or () if f not in differential_fields()]
    if bad:
        raise ReplayError(
            f"{where}: differential {shown(bad[0])}: only pose fields are differential (position: deltas as "
            f"a body velocity, attitude: as body rates); fuse {shown(bad[0])} as it is"
        )
    both = [f for f in fuse or () if f in (differential or ())]
    if both:
        raise ReplayError(
            f"{where}: {shown(both[0])} is in both fuse and differential: a field is used one way "
            "(absolute in fuse, or as deltas in differential)"
        )


class Mount(NamedTuple):
    """A sensor's mounting in the body frame, as a static transform body -> sensor frame:
    ``rotation`` (roll, pitch, yaw, rad: R_m, the sensor's axes in the body's), ``translation``
    (x, y, z in m: the sensor's origin in the body frame, a GPS antenna's lever arm), the two
    frames."""

    rotation: tuple[float, float, float]
    translation: tuple[float, float, float]
    parent: str
    child: str

    def as_dict(self) -> dict:
        return {
            "parent": self.parent,
            "child": self.child,
            "rotation": list(self.rotation),
            "translation": list(self.translation),
        }


@dataclass(frozen=True)
class SensorInput:
    """One sensor input of a frame: an entry of ``role`` whose fields are the channels
    ``channels`` (field -> channel name), read from ``source`` (topic and type, or columns).

    ``declared``: its role was declared (not the message kind's default). The fusion task's
    settings of the entry, None where not declared: ``fuse`` and ``differential`` (field
    lists), ``noise`` (field -> variance), ``rejection_threshold`` (a Mahalanobis distance, or
    field -> distance), ``twist_frame`` (``child`` or ``parent``), ``mount`` (declared
    [roll, pitch, yaw] of the sensor in the body frame), ``lever_arm`` (declared [x, y, z] of a GPS
    antenna in the body frame). Found by the adapter:
    ``attitude_enu`` (its attitude was checked east-north-up), ``recorded_mount`` (the
    recording's static transform body -> the message's frame, a :class:`Mount`)."""

    role: str
    entry: str
    source: str
    channels: dict = field(default_factory=dict)
    declared: bool = False
    fuse: tuple | None = None
    differential: tuple | None = None
    noise: dict | None = None
    rejection_threshold: float | dict | None = None
    twist_frame: str | None = None
    mount: tuple | None = None
    lever_arm: tuple | None = None
    attitude_enu: bool | None = None
    recorded_mount: Mount | None = None

    @property
    def spec(self) -> Role:
        """Its :class:`Role` (a ReplayError naming the entry when the role is unknown)."""
        if self.role not in ROLES:
            raise ReplayError(
                f"{self.entry}: unknown role {shown(self.role)} (known: {', '.join(ROLES)}; docs/architecture.md, "
                "\"Add a sensor role\")"
            )
        return ROLES[self.role]

    def as_dict(self) -> dict:
        """Its entry in a manifest's ``roles`` (the keys that are set)."""
        out = {"entry": self.entry, "source": self.source, "declared": self.declared, "channels": dict(self.channels)}
        for key in (
            "twist_frame",
            "mount",
            "lever_arm",
            "fuse",
            "differential",
            "noise",
            "rejection_threshold",
            "attitude_enu",
        ):
            value = getattr(self, key)
            if value is not None:
                out[key] = list(value) if isinstance(value, tuple) else value
        if self.recorded_mount is not None:
            out["recorded_mount"] = self.recorded_mount.as_dict()
        return out


def make_input(role: str, entry: str, source: str, channels: dict, declared: bool = False, **settings) -> SensorInput:
    """A :class:`SensorInput` from a mapping entry's settings (lists as tuples, numbers as floats)."""
    for key in ("fuse", "differential", "mount", "lever_arm"):
        if settings.get(key) is not None:
            settings[key] = tuple(settings[key])
    return SensorInput(role, entry, source, dict(channels), declared, **settings)


def ordered(inputs) -> list[SensorInput]:
    """The inputs of every role but ``none``, roles in :data:`ROLES` order (each role's in the
    adapter's order); an unknown role is refused (:attr:`SensorInput.spec`)."""
    inputs = [i for i in inputs or () if i.role != NONE]
    for i in inputs:
        i.spec  # refuses an unknown role
    return [i for name in ROLES for i in inputs if i.role == name]


def of_role(inputs, name: str) -> list[SensorInput]:
    return [i for i in inputs or () if i.role == name]


def as_meta(inputs) -> dict:
    """``{role: [entry, ...]}``: the inputs as a manifest records them."""
    out: dict = {}
    for i in inputs or ():
        out.setdefault(i.role, []).append(i.as_dict())
    return out
