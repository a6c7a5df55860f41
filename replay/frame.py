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
* **Report**: the adapter's account of every sample or channel it dropped,
  flagged, masked or repaired. Nothing is removed silently.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


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
        return Channel(self.values[index], self.unit, self.frame, self.valid[index],
                       self.components, self.angles, self.convention, self.description)


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
        return [e for e in self.entries
                if (action is None or e.action == action) and (what is None or e.what == what)]

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

    def __post_init__(self):
        self.t = np.asarray(self.t, dtype=float)
        if self.t.ndim != 1:
            raise ValueError("time axis must be one-dimensional")
        if len(self.t) > 1 and not np.all(np.diff(self.t) > 0):
            raise ValueError("time axis must be strictly increasing")
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
        meta = dict(self.meta, first=int(n))
        return Frame(self.t[sl], {k: c.take(sl) for k, c in self.channels.items()},
                     {k: c.take(sl) for k, c in self.reference.items()},
                     self.epoch, meta, self.report)

    def summary(self) -> list[str]:
        """Human-readable lines: span, channels, reference, report."""
        out = []
        span = self.t[-1] - self.t[0] if len(self.t) else 0.0
        dt = np.median(np.diff(self.t)) if len(self.t) > 1 else float("nan")
        out.append(f"samples {len(self.t)}, span {span:.1f} s, median step {dt:.4f} s")
        for kind, group in (("channel", self.channels), ("reference", self.reference)):
            for name, ch in group.items():
                comp = f" [{', '.join(ch.components)}]" if ch.components else ""
                out.append(f"{kind:9s} {name}{comp}: {ch.unit}, {ch.frame or '-'}, "
                           f"{int(ch.valid.sum())}/{len(ch)} valid")
        return out
