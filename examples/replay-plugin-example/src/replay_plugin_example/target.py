"""A constant-velocity target tracked from range and bearing: the example plugin's model, task and simulator.

* :class:`RangeBearingCV` — the model protocol of replay (``replay/model.py``): state
  ``[x, y, vx, vy]`` (m, m/s; x east, y north), ``f`` and ``h`` on arrays of states
  ``(..., 4)``; the measurement ``[range, bearing]`` of a sensor at ``sensor``, the
  bearing a declared angle (``z_angles = (1,)``: residuals wrapped, means circular).
* :class:`RangeBearingTask` (``example-range-bearing``) — a task: reads the frame's
  ``range`` and ``bearing`` channels (NaN where not valid), scores against the
  reference ``position``; declared parameters.
* :func:`make_frame` (``example/range-bearing``) — a seeded simulator with declared
  parameters, producing a :class:`replay.frame.Frame`.
"""
from __future__ import annotations

import numpy as np

from replay.frame import Channel, Frame
from replay.model import Model
from replay.sim import generator
from replay.tasks import Problem, Task, describe, missing
from replay.util.angles import wrap
from replay.util.params import Param

POSITIVE = dict(low=0.0, low_open=True)


def white_acceleration(q: float, dt: float) -> np.ndarray:
    """Process covariance of a constant-velocity state [x, y, vx, vy] under white acceleration q."""
    block = q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    Q = np.zeros((4, 4))
    for axis in (0, 1):
        Q[np.ix_([axis, axis + 2], [axis, axis + 2])] = block
    return Q


class RangeBearingCV(Model):
    """Constant velocity in the plane, observed in range (m) and bearing (rad, from east, anticlockwise)."""

    nx, nz = 4, 2
    z_angles = (1,)

    def __init__(self, dt: float, q: float, sigma_range: float, sigma_bearing: float, sensor=(0.0, 0.0)):
        self.dt, self.sensor = float(dt), np.asarray(sensor, float)
        self.A = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1]], float)
        self.Q = white_acceleration(q, dt)
        self.R = np.diag([sigma_range ** 2, sigma_bearing ** 2])

    def f(self, x, k):
        return x @ self.A.T

    def F(self, x, k):
        return self.A

    def h(self, x, k):
        d = x[..., :2] - self.sensor
        return np.stack([np.hypot(d[..., 0], d[..., 1]), np.arctan2(d[..., 1], d[..., 0])], axis=-1)

    def H(self, x, k):
        dx, dy = x[0] - self.sensor[0], x[1] - self.sensor[1]
        r2 = dx * dx + dy * dy
        r = np.sqrt(r2)
        return np.array([[dx / r, dy / r, 0.0, 0.0], [-dy / r2, dx / r2, 0.0, 0.0]])


class RangeBearingTask(Task):
    """``example-range-bearing``: a constant-velocity target tracked from range and bearing (example plugin)."""

    name = "example-range-bearing"
    LOST_M = 100.0  # m: range noise 10 m at 1-2 km; a working filter stays within about 20 m
    PARAMS = (
        Param("q", float, 0.05, "white-acceleration intensity the filters assume", unit="m^2/s^3", **POSITIVE),
        Param("sigma_range", float, 10.0, "range noise standard deviation the filters assume", unit="m",
              **POSITIVE),
        Param("sigma_bearing", float, 0.01, "bearing noise standard deviation the filters assume", unit="rad",
              **POSITIVE),
        Param("p0", float, 400.0, "prior variance of each position axis (velocity: p0 / 4 in m^2/s^2)",
              unit="m^2", **POSITIVE),
    )

    def build(self, frame, rng):
        for name in ("range", "bearing"):
            if name not in frame.channels:
                raise missing(frame, self.name, f"a {name!r} channel (replay datasets info shows the frame)", (name,))
        ref = frame.reference.get("position")
        if ref is None:
            raise missing(frame, self.name, "a reference position to score against", ("position",))
        rng_ch, brg = frame.channels["range"], frame.channels["bearing"]
        valid = rng_ch.valid & brg.valid
        if not valid.any():
            raise missing(frame, self.name, "at least one valid range and bearing", ("range", "bearing"))
        z = np.where(valid[:, None], np.column_stack([rng_ch.values, brg.values]), np.nan)
        dt = float(np.median(np.diff(frame.t))) if len(frame.t) > 1 else 1.0
        sensor = SENSOR  # where the simulator puts it (a task's inputs are channels and records, not meta)
        model = RangeBearingCV(dt, self.q, self.sigma_range, self.sigma_bearing, sensor)
        first = int(np.argmax(valid))  # the prior: the first valid fix, at rest, one step before it
        r, b = z[first]
        x0 = np.array([sensor[0] + r * np.cos(b), sensor[1] + r * np.sin(b), 0.0, 0.0])
        P0 = np.diag([self.p0, self.p0, self.p0 / 4, self.p0 / 4])
        truth = np.asarray(ref.values, float)[:, :2]
        return Problem(model, z, x0, P0, frame.t, truth, ref.valid.copy(), (0, 1), ("x", "y"),
                       params=self.params(),
                       inputs={"range": describe(frame, "range"), "bearing": describe(frame, "bearing"),
                               "reference": describe(frame, "position", "reference")})


SENSOR = (0.0, 0.0)  # the sensor's position, east and north (m)

PARAMS = (
    Param("steps", int, 300, "number of samples", low=2),
    Param("dt", float, 1.0, "time step", unit="s", **POSITIVE),
    Param("q", float, 0.05, "white-acceleration intensity of the target", unit="m^2/s^3", **POSITIVE),
    Param("sigma_range", float, 10.0, "range noise standard deviation", unit="m", **POSITIVE),
    Param("sigma_bearing", float, 0.01, "bearing noise standard deviation", unit="rad", **POSITIVE),
    Param("dropout", float, 0.05, "probability that a fix is missing", low=0.0, high=1.0, high_open=True),
)


@generator(PARAMS)
def make_frame(rng: np.random.Generator, *, steps, dt, q, sigma_range, sigma_bearing, dropout) -> Frame:
    """A target crossing at about 10 m/s, 1-2 km from a range-bearing sensor (example plugin's simulator)."""
    model = RangeBearingCV(dt, q, sigma_range, sigma_bearing, SENSOR)
    x = np.array([-1500.0, 800.0, 10.0, -2.0])
    L = np.linalg.cholesky(model.Q)
    truth = np.empty((steps, 4))
    for k in range(steps):
        x = model.f(x, k) + L @ rng.standard_normal(4)
        truth[k] = x
    z = model.h(truth, 0) + rng.standard_normal((steps, 2)) * [sigma_range, sigma_bearing]
    z[:, 1] = wrap(z[:, 1])
    ok = rng.random(steps) >= dropout
    t = np.arange(steps) * dt
    channels = {
        "range": Channel(z[:, 0], "m", "sensor", valid=ok, description="range to the target"),
        "bearing": Channel(z[:, 1], "rad", "sensor", valid=ok.copy(), angles=(0,),
                           convention="from east, anticlockwise", description="bearing of the target"),
    }
    reference = {"position": Channel(np.column_stack([truth[:, :2], np.zeros(steps)]), "m", "enu",
                                     components=("east", "north", "up"), description="simulated target")}
    meta = {"source": "synthetic: replay_plugin_example.target", "synthetic": True, "crs": None}
    return Frame(t, channels, reference, None, meta)


make_frame.DEFAULT_TASK = "example-range-bearing"
