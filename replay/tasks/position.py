"""``position``: the Bohai experiment of paper 002 (benchmark 3), as the digest reads it.

State: 3-D position, random walk with Q = diag(1, 1, 1) per sample; prior at the
start point with P0 = diag(0.1, 0.1, 0.1); measurements: the reference position
plus seeded Gaussian noise R = 2 I3 (the paper prints "R = 2 x eye(1)"); one
filter step per sample (the paper's T = 1 s per sample, whatever the log's rate).

Where the reference is masked (jumps of the navigation solution), no
measurement is synthesised: the filters predict only, and the scorer skips
those samples. The vertical of the Bohai files is not observed (``depth`` is
all zero), so z is constant at ``z0``: by default minus the first valid GPS
altitude, as the paper's start point (0, 0, -12.0941) suggests.
"""

from __future__ import annotations

import numpy as np

from replay.models.random_walk import RandomWalkPosition
from replay.util.params import Param

from . import Problem, Task, describe, reference_position_3d

POSITIVE = dict(low=0, low_open=True)


class PositionTask(Task):
    name = "position"
    SYNTHETIC = True  # measurements drawn from the reference (the paper's protocol)
    LOST_M = 10.0  # lost-track threshold (m): navigation-solution reference; working filters stay near 1-2 m
    PARAMS = (
        Param("q", float, 1.0, "process noise variance per axis and sample (Q = q I3)", unit="m^2", **POSITIVE),
        Param("r", float, 2.0, "measurement noise variance per axis (R = r I3; 002 prints 2)", unit="m^2", **POSITIVE),
        Param("p0", float, 0.1, "prior variance per axis (P0 = p0 I3)", unit="m^2", **POSITIVE),
        Param(
            "z0",
            float,
            None,
            "constant vertical position; null = minus the first GPS altitude",
            unit="m",
            optional=True,
        ),
    )

    def build(self, frame, rng):
        z0 = self.z0
        inputs = {"reference": describe(frame, "position", "reference")}
        if z0 is None:
            name = "gps_alt" if "gps_alt" in frame.channels else "alt"
            alt = frame.channels.get(name)
            z0 = -float(alt.values[alt.valid][0]) if alt is not None and alt.valid.any() else 0.0
            inputs["z0"] = (
                f"minus the first valid {describe(frame, name)}"
                if alt is not None and alt.valid.any()
                else "0 (no altitude channel)"
            )
        truth, valid = reference_position_3d(frame, z0, task="position")
        model = RandomWalkPosition(self.q * np.eye(3), self.r * np.eye(3))
        noise = rng.standard_normal(truth.shape) * np.sqrt(self.r)
        z = np.where(valid[:, None], truth + noise, np.nan)
        first = int(np.argmax(valid))
        x0 = truth[first].copy()
        return Problem(
            model,
            z,
            x0,
            self.p0 * np.eye(3),
            frame.t,
            truth,
            valid,
            (0, 1, 2),
            ("x", "y", "z"),
            params=dict(self.params(), z0_used=z0),
            inputs=inputs,
        )
