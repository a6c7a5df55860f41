"""The common timestamped sensor frame.

Every adapter produces a :class:`Frame`; every task consumes one. Conventions:

* **Time** ``t`` is a strictly increasing float64 array of seconds from the
  first sample. ``epoch`` is the absolute time of ``t = 0`` in seconds since
  the Unix epoch (UTC) when the source has one, otherwise ``None``.
* **Positions** are in a local east-north-up (ENU) tangent frame, in metres,
  obtained from a projected CRS (UTM for geodetic sources: ``meta["crs"]`` is the
  EPSG code, ``meta["origin"]`` the projected coordinates of the local origin).
* **Depth** is positive down, in metres. **Up** (``z`` of a position) is
  positive up, so ``up = -depth`` where both exist.
* **Angles** are radians. Each angle channel declares its convention in
  ``Channel.convention`` (e.g. "heading: 0 = east, counter-clockwise positive").
* **Channels** are named arrays of shape ``(n,)`` or ``(n, k)`` aligned with
  ``t``, with a unit, a frame and a per-sample validity mask. Samples that are
  not valid are kept (so arrays stay aligned with ``t``) but must not be used.
* **Reference** channels (ground truth, external reference) live in
  ``Frame.reference``, apart from the sensor ``Frame.channels``. Tasks read the
  reference only to score, or to synthesise measurements as a paper's protocol
  prescribes; no filter is ever handed a Frame.
* **Recorded estimates** (``Frame.estimates``, :class:`RecordedEstimate`): what
  an estimator already wrote into the recording (an onboard EKF's odometry, a
  SLAM system's poses, a vendor INS solution). Each keeps its own stamps (seconds
  on the origin of ``t``, not merged into the time axis, so declaring one never
  changes what the filters see), its positions in the recording's frame, its
  orientation and its position covariance when recorded. They are data for the
  scorer (leaderboard rows ``recorded:<name>``), never inputs of a filter.
* **Roles** (``Frame.roles``): the sensor inputs the adapter found, typed records
  (:class:`replay.roles.SensorInput`: role, entry, source, channels by field, the mapping's
  fusion settings); tasks find their inputs by role through them. None: the adapter declares
  none (simulated frames; tasks fall back to channels named after the role).
* **Simulation** (``Frame.simulation``, :class:`Simulation`): how a simulator made the
  frame (its parameters as validated, its step, the true state a paper's protocol starts
  its filters from); None for a recording. **Maneuvers** (``Frame.maneuvers``): labelled
  ``(start, end, label)`` segments on ``t`` that scoring can split by (a lake trial's
  pitch commands); views move them with the time axis. **Columns**
  (``Frame.columns``): the source columns each channel is made of (CSV adapters), so a
  missing input can be traced to the column the report dropped. **Default task**
  (``Frame.default_task``): the task the adapter's data is for, when it declares one.
* **Meta** (``Frame.meta``): metadata only (source, CRS and origin, checksums, what the
  adapter found): read to describe and record, never as a task's input.
* **Report**: the adapter's account of every sample or channel it dropped,
  flagged, masked or repaired. Nothing is removed silently.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np
from replay.util.dataframes import frame_table


@dataclass
class Channel:
    """One named signal aligned with the frame's time axis."""

    values: np.ndarray
    unit: str
    frame: str = ""
    valid: np.ndarray | None = None
    components: tuple[str, ...] = ()
    angles: tuple[int, ...] = ()
    convention: str = ""
    description: str = ""

    def __post_init__(self):
        self.values = np.asarray(self.values, dtype=float)
        if self.valid is None:
            v = self.values if self.values.ndim == 1 else self.values.reshape(len(self.values), -1)
            self.valid = np.isfinite(v) if v.ndim == 1 else np.isfinite(v).all(axis=1)
        self.valid = np.asarray(self.valid, dtype=bool)
        if self.valid.shape != (len(self.values),):
            raise ValueError("validity mask must have one entry per sample")

    def __len__(self):
        return len(self.values)

    @property
    def width(self) -> int:
        return 1 if self.values.ndim == 1 else self.values.shape[1]

    def take(self, index) -> "Channel":
        return Channel(
            self.values[index],
            self.unit,
            self.frame,
            self.valid[index],
            self.components,
            self.angles,
            self.convention,
            self.description,
        )


@dataclass
class RecordedEstimate:
    """A trajectory an estimator recorded: one pose per stamp, on its own stamps.

    ``t`` (m,) strictly increasing seconds on the frame's origin (may start before
    or end after the frame's axis); ``position`` (m, 3) in ``frame`` (the
    recording's parent frame, or local ENU for a NavSatFix); ``orientation`` (m, 4)
    unit quaternions x, y, z, w or None when not recorded; ``covariance`` (m, 3, 3)
    position covariance (NaN where a message has none) or None when never recorded;
    ``child`` the body frame when known; ``params`` association settings from the
    mapping (``t_max_diff``, ``t_offset``), the defaults of its leaderboard row.
    """

    t: np.ndarray
    position: np.ndarray
    orientation: np.ndarray | None = None
    covariance: np.ndarray | None = None
    frame: str = ""
    child: str = ""
    description: str = ""
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        self.t = np.asarray(self.t, dtype=float)
        pos = np.asarray(self.position, dtype=float)
        self.position = pos.reshape(len(self.t), -1) if pos.size else pos.reshape(0, 3)
        if self.t.ndim != 1 or (len(self.t) > 1 and not np.all(np.diff(self.t) > 0)):
            raise ValueError("recorded estimate stamps must be one-dimensional and strictly increasing")
        for name, shape in (("orientation", (len(self.t), 4)), ("covariance", (len(self.t), 3, 3))):
            value = getattr(self, name)
            if value is not None:
                value = np.asarray(value, dtype=float)
                if value.shape != shape:
                    raise ValueError(f"recorded estimate {name} must have shape {shape}, got {value.shape}")
                setattr(self, name, value)

    def __len__(self):
        return len(self.t)

    def until(self, t_end: float) -> "RecordedEstimate":
        """The poses stamped at or before ``t_end``."""
        keep = self.t <= t_end
        pick = lambda a: None if a is None else a[keep]
        return RecordedEstimate(
            self.t[keep],
            self.position[keep],
            pick(self.orientation),
            pick(self.covariance),
            self.frame,
            self.child,
            self.description,
            dict(self.params),
        )


@dataclass(frozen=True)
class Simulation:
    """How a simulator made a frame: what a paper's protocol lets a task know of the truth.

    ``generator`` the simulator's module; ``params`` its parameters as validated, one attribute
    per declaration (a frozen record, filled in by :func:`replay.sim.generator`); ``dt`` the
    generation step in seconds (None: the simulator has none); ``initial_state`` the true
    state its task starts from, components named by ``state`` (sim/ungm and sim/auv-sonar:
    ``x0`` at the step before the first sample; sim/sauv-current: the NED state at the first
    sample); None when its task does not start from the truth. A frame with an initial state
    takes only views that keep its first sample and its step (:mod:`replay.data.views`).
    """

    generator: str = ""
    params: object = None
    dt: float | None = None
    initial_state: tuple[float, ...] | None = None
    state: tuple[str, ...] = ()

    def __post_init__(self):
        if self.initial_state is not None:
            x0 = tuple(float(x) for x in np.asarray(self.initial_state, float).ravel())
            if self.state and len(self.state) != len(x0):
                raise ValueError(f"initial state of {len(x0)} components, {len(self.state)} named")
            object.__setattr__(self, "initial_state", x0)

    def start(self, state: tuple[str, ...], who: str) -> np.ndarray:
        """The initial state as an array, refused in one line unless its components are ``state``."""
        if self.initial_state is None or self.state != tuple(state):
            raise ValueError(
                f"{who}: needs a simulated initial state ({', '.join(state)}); "
                f"{self.generator or 'this simulation'} has {', '.join(self.state) or 'none'}"
            )
        return np.array(self.initial_state, float)

    def as_meta(self) -> dict:
        """Plain values for a manifest: generator, step, initial state and the parameters."""
        params = self.params
        if params is not None and not isinstance(params, dict):
            params = {f.name: getattr(params, f.name) for f in fields(params)}
        out = {"generator": self.generator, "dt": self.dt}
        if self.initial_state is not None:
            out.update(initial_state=list(self.initial_state), state=list(self.state))
        return out | {"params": params or {}}


@dataclass
class ReportEntry:
    action: str  # "dropped", "flagged", "masked", "repaired", "info"
    what: str  # the channel, column or rows concerned
    count: int  # samples (or columns) concerned
    reason: str

    def line(self) -> str:
        return f"{self.action:8s} {self.count:7d}  {self.what}: {self.reason}"


@dataclass
class Report:
    """What an adapter did to the source data."""

    entries: list[ReportEntry] = field(default_factory=list)

    def add(self, action: str, what: str, count: int, reason: str) -> None:
        self.entries.append(ReportEntry(action, what, int(count), reason))

    def find(self, action: str | None = None, what: str | None = None) -> list[ReportEntry]:
        return [e for e in self.entries if (action is None or e.action == action) and (what is None or e.what == what)]

    def count(self, action: str) -> int:
        return sum(e.count for e in self.entries if e.action == action)

    def lines(self) -> list[str]:
        return [e.line() for e in self.entries]

    def to_list(self) -> list[dict]:
        return [e.__dict__.copy() for e in self.entries]


@dataclass
class Frame:
    """Sensor channels and reference channels on one time axis."""

    t: np.ndarray
    channels: dict[str, Channel] = field(default_factory=dict)
    reference: dict[str, Channel] = field(default_factory=dict)
    epoch: float | None = None
    meta: dict = field(default_factory=dict)
    report: Report = field(default_factory=Report)
    estimates: dict[str, RecordedEstimate] = field(default_factory=dict)
    # the sensor inputs the adapter found (replay.roles.SensorInput); None: it declares none
    roles: tuple | None = None
    simulation: Simulation | None = None  # how a simulator made it; None: a recording
    maneuvers: tuple[tuple[float, float, str], ...] = ()  # labelled (start, end, label) segments on t
    columns: dict[str, tuple[str, ...]] = field(default_factory=dict)  # channel -> the source columns it is made of
    default_task: str | None = None  # the task the adapter's data is for, when it declares one

    def to_pandas(self, *, reference: bool = False, masks: bool = False, time: str = "relative"):
        """The sensor channels (``reference=True``: the reference) as a DataFrame (:mod:`replay.util.dataframes`)."""
        return frame_table(self, reference=reference, masks=masks, time=time)

    def __post_init__(self):
        self.t = np.asarray(self.t, dtype=float)
        if self.t.ndim != 1:
            raise ValueError("time axis must be one-dimensional")
        if len(self.t) > 1 and not np.all(np.diff(self.t) > 0):
            raise ValueError("time axis must be strictly increasing")
        self.maneuvers = tuple((float(a), float(b), str(label)) for a, b, label in self.maneuvers)
        self.columns = {name: tuple(cols) for name, cols in self.columns.items()}
        for group in (self.channels, self.reference):
            for name, ch in group.items():
                if len(ch) != len(self.t):
                    raise ValueError(f"channel {name!r} has {len(ch)} samples, time axis {len(self.t)}")

    def __len__(self):
        return len(self.t)

    def head(self, n: int) -> "Frame":
        """The first ``n`` samples (all of them when ``n`` is None or larger)."""
        if n is None or n >= len(self.t):
            return self
        sl = slice(0, int(n))
        end = float(self.t[int(n) - 1])  # recorded estimates and maneuvers: those within the kept span
        return replace(
            self,
            t=self.t[sl],
            channels={k: c.take(sl) for k, c in self.channels.items()},
            reference={k: c.take(sl) for k, c in self.reference.items()},
            meta=dict(self.meta, first=int(n)),
            estimates={k: e.until(end) for k, e in self.estimates.items()},
            maneuvers=tuple(m for m in self.maneuvers if m[0] <= end),  # as they were: t < end of each holds
        )

    def records(self) -> dict:
        """The typed records beside the metadata (simulation, maneuvers, columns, default task), those set,
        as plain values: a manifest's "dataset" section is ``meta`` with these."""
        out = {"simulation": self.simulation.as_meta()} if self.simulation is not None else {}
        if self.maneuvers:
            out["maneuvers"] = [list(m) for m in self.maneuvers]
        if self.columns:
            out["columns"] = {name: list(cols) for name, cols in self.columns.items()}
        return out | ({"default_task": self.default_task} if self.default_task else {})

    def summary(self) -> list[str]:
        """Human-readable lines: span, channels, reference, report."""
        out = []
        span = self.t[-1] - self.t[0] if len(self.t) else 0.0
        dt = np.median(np.diff(self.t)) if len(self.t) > 1 else float("nan")
        out.append(f"samples {len(self.t)}, span {span:.1f} s, median step {dt:.4f} s")
        for kind, group in (("channel", self.channels), ("reference", self.reference)):
            for name, ch in group.items():
                comp = f" [{', '.join(ch.components)}]" if ch.components else ""
                out.append(
                    f"{kind:9s} {name}{comp}: {ch.unit}, {ch.frame or '-'}, {int(ch.valid.sum())}/{len(ch)} valid"
                )
        for name, est in self.estimates.items():
            span = f"{est.t[0]:.1f}..{est.t[-1]:.1f} s" if len(est) else "empty"
            extra = [w for w, v in (("orientation", est.orientation), ("covariance", est.covariance)) if v is not None]
            out.append(
                f"estimate  {name}: {len(est)} poses, {span}, {est.frame or '-'}"
                + (f" -> {est.child}" if est.child else "")
                + (f", with {' and '.join(extra)}" if extra else "")
            )
        return out
