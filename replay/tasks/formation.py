"""``formation``: the follower UAV of paper 003 tracks itself from radar range/bearing to the leader.

Model :class:`replay.models.formation.Formation` built from the frame's
``leader_position`` and ``turn_rate`` channels and the generator's noise
figures; the measurement noise is the glint mixture (003 eq. 7–10) with the
frame's ε unless ``eps`` is given (the filters may then assume a glint
strength different from the simulated one). Prior: x₀ ~ N(x_true0, P0) drawn
once from the task's seed, P0 = diag(10², 10², 1, 1) by default (ours: the paper does not
say how it initialises). Scored: position x, y; velocity vx, vy as extra
components.
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import ReplayError
from replay.util.params import Param
from replay.models.formation import Formation
from replay.models.noise import Covariance, as_matrix
from replay.sim.uav_formation import glint_003

from . import Problem, Task, simulated, simulated_start


class FormationTask(Task):
    name = "formation"
    LOST_M = 20.0  # lost-track threshold (m): working filters stay near 1-2 m
    PARAMS = (
        Param(
            "eps",
            float,
            None,
            "glint probability the filters assume; null = the simulator's",
            low=0,
            high=1,
            optional=True,
        ),
        Covariance(
            "P0",
            list,
            (100.0, 100.0, 1.0, 1.0),
            "prior covariance of [x, y, vx, vy] (ours)",
            unit="m^2, (m/s)^2",
            dim=4,
        ),
    )

    def build(self, frame, rng):
        need = ("radar", "leader_position", "turn_rate")
        if any(c not in frame.channels for c in need):
            raise ReplayError(f"{frame.meta.get('dataset', 'frame')}: formation needs channels {', '.join(need)}")
        sim = {k: simulated(frame, k, self.name) for k in ("range_sigma", "sigma1", "sigma2", "accel_sigma")}
        eps = simulated(frame, "eps", self.name, "give it as a task parameter") if self.eps is None else self.eps
        noise = glint_003(eps, sim["range_sigma"], sim["sigma1"], sim["sigma2"])
        x_true0 = simulated_start(frame, ("x", "y", "vx", "vy"), self.name)
        model = Formation(
            frame.channels["leader_position"].values,
            frame.channels["turn_rate"].values,
            frame.simulation.dt,
            sim["accel_sigma"] ** 2 * np.eye(2),
            noise,
        )
        radar = frame.channels["radar"]
        z = np.where(radar.valid[:, None], radar.values, np.nan)
        P0 = as_matrix(self.P0)
        x0 = x_true0 + np.linalg.cholesky(P0) @ rng.standard_normal(4)
        ref = frame.reference
        pb = Problem(
            model,
            z,
            x0,
            P0,
            frame.t,
            ref["position"].values,
            ref["position"].valid.copy(),
            (0, 1),
            ("x", "y"),
            params=self.params(),
        )
        vel = ref["velocity"]
        pb.truth_extra = {"vx": (vel.values[:, 0], 2), "vy": (vel.values[:, 1], 3)}
        pb.extra_units = {"vx": vel.unit, "vy": vel.unit}
        return pb
