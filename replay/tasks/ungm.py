"""``ungm``: filter the UNGM measurements of ``sim/ungm`` (paper 002, §3.2).

The model's Q, R and growth are the simulator's (``frame.simulation.params``)
unless given. Prior: x_0 = the simulator's initial state (0)
with P0 = ``p0`` (002 gives x_0 = 0 and no P0; we take 1).
"""

from __future__ import annotations

import numpy as np

from replay.models.ungm import UNGM
from replay.util.params import Param

from . import Problem, Task, simulated, simulated_start
from replay.util.errors import ReplayError


class UNGMTask(Task):
    name = "ungm"
    # lost-track threshold (m): state units; the sign ambiguity of x^2/20 puts a wrong-mode estimate about 2|x| away
    LOST_M = 10.0
    PARAMS = (
        Param(
            "q",
            float,
            None,
            "process noise variance the filters assume; null = the simulator's",
            low=0,
            low_open=True,
            optional=True,
        ),
        Param(
            "r",
            float,
            None,
            "measurement noise variance the filters assume; null = the simulator's",
            low=0,
            low_open=True,
            optional=True,
        ),
        Param("p0", float, 1.0, "prior variance (002 gives none)", low=0, low_open=True),
        Param("growth", float, None, "growth coefficient g the filters assume; null = the simulator's", optional=True),
    )

    def build(self, frame, rng):
        if "z" not in frame.channels or "position" not in frame.reference:
            raise ReplayError("task ungm: needs a frame from sim/ungm (channel 'z', reference 'position')")
        hint = "give it as a task parameter"
        q = simulated(frame, "q", self.name, hint) if self.q is None else self.q
        r = simulated(frame, "r", self.name, hint) if self.r is None else self.r
        g = simulated(frame, "growth", self.name, hint) if self.growth is None else self.growth
        model = UNGM(q, r, g)
        ch, ref = frame.channels["z"], frame.reference["position"]
        z = np.where(ch.valid[:, None], ch.values, np.nan)
        x0 = simulated_start(frame, ("x",), self.name)
        return Problem(
            model,
            z,
            x0,
            np.array([[self.p0]]),
            frame.t,
            ref.values,
            ref.valid.copy(),
            (0,),
            ("x",),
            params={"q": q, "r": r, "growth": g, "p0": self.p0},
            position_unit="1",
        )  # UNGM is dimensionless
