"""``linear``: a Kalman filter's model of ``sim/linear`` (3-D random walk observed directly).

The filters assume Q = q I3 and R = r I3 (task parameters, by default 1 and 1,
not the simulator's truth: what tuning should find). Prior: x_0 = 0, P0 = p0 I3.
"""

from __future__ import annotations

import numpy as np

from replay.models.random_walk import RandomWalkPosition
from replay.util.errors import ReplayError
from replay.util.params import Param

from . import Problem, Task

POSITIVE = dict(low=0, low_open=True)


class LinearTask(Task):
    name = "linear"
    LOST_M = 20.0  # lost-track threshold (m): far beyond the measurement noise of any sensible r
    PARAMS = (
        Param("q", float, 1.0, "process noise variance per axis the filters assume (Q = q I3)", unit="m^2", **POSITIVE),
        Param(
            "r", float, 1.0, "measurement noise variance per axis the filters assume (R = r I3)", unit="m^2", **POSITIVE
        ),
        Param("p0", float, 1.0, "prior variance per axis (P0 = p0 I3) around x_0 = 0", unit="m^2", **POSITIVE),
    )

    def build(self, frame, rng):
        if "z" not in frame.channels or "position" not in frame.reference:
            raise ReplayError("task linear: needs a frame from sim/linear (channel 'z', reference 'position')")
        ch, ref = frame.channels["z"], frame.reference["position"]
        z = np.where(ch.valid[:, None], ch.values, np.nan)
        model = RandomWalkPosition(self.q * np.eye(3), self.r * np.eye(3))
        return Problem(
            model,
            z,
            np.zeros(3),
            self.p0 * np.eye(3),
            frame.t,
            ref.values,
            ref.valid.copy(),
            (0, 1, 2),
            ("x", "y", "z"),
            params=self.params(),
        )
