"""``sonar``: an AUV tracked by one sonar (paper 002, benchmark 2 model).

State [x, y, z, v, pitch, yaw] (:class:`replay.models.auv_sonar.AUVSonar`),
measurements range/elevation/azimuth with R = diag(2, 0.01^2, 0.01^2).

* On a frame with a ``sonar`` channel (``sim/auv-sonar``) the filters see that
  channel; the prior is the generator's initial state drawn once with P0
  (x0 ~ N(x_true0, P0), from the run's data seed): the paper does not say how
  its filters are initialised.
* On any other frame with a reference position (e.g. Bohai) the sonar sits at
  the first reference sample and its measurements are synthesised from the
  reference with seeded noise R; step length is the frame's time step. The
  prior is the start point with zero speed, pitch and yaw and a wide P0.
"""

from __future__ import annotations

import numpy as np

from replay.util.angles import wrap
from replay.util.params import Param
from replay.models.auv_sonar import P0_TABLE2, Q_TABLE2, R_TABLE2, AUVSonar
from replay.models.noise import Covariance, as_matrix, diagonal

from replay.sim.auv_sonar import STATE
from . import Problem, Task, describe, reference_position_3d, simulated, simulated_start


class SonarTask(Task):
    name = "sonar"
    SYNTHETIC = True  # measurements drawn from the reference (the paper's protocol)
    LOST_M = 20.0  # lost-track threshold (m): range noise std 1.4 m; working filters stay near 2-3 m
    PARAMS = (
        Covariance("Q", list, diagonal(Q_TABLE2), "process noise covariance the filters assume (Table 2)", dim=6),
        Covariance(
            "R",
            list,
            diagonal(R_TABLE2),
            "sonar noise covariance the filters assume, range/elevation/azimuth (Table 2)",
            unit="m^2, rad^2",
            dim=3,
        ),
        Covariance(
            "P0",
            list,
            None,
            "prior covariance; null = Table 2's on a sonar frame, diag(1, 1, 1, 4, 0.1, pi^2) otherwise",
            dim=6,
            optional=True,
        ),
        Param(
            "yaw_rate",
            float,
            None,
            "yaw rate of the model; null = the simulator's (0 on other frames)",
            unit="rad/s",
            optional=True,
        ),
    )

    def build(self, frame, rng):
        Q, R, P0 = as_matrix(self.Q), as_matrix(self.R), as_matrix(self.P0)
        truth, valid = reference_position_3d(frame, task="sonar")
        if "sonar" in frame.channels:
            x_true0 = simulated_start(frame, STATE, self.name)
            yaw_rate = self.yaw_rate
            if yaw_rate is None:
                yaw_rate = simulated(frame, "yaw_rate", self.name, "give it as a task parameter")
            model = AUVSonar(Q, R, dt=frame.simulation.dt, yaw_rate=yaw_rate)  # the sonar at the origin, as simulated
            ch = frame.channels["sonar"]
            z = np.where(ch.valid[:, None], ch.values, np.nan)
            P0 = P0_TABLE2 if P0 is None else P0
            x0 = x_true0 + np.linalg.cholesky(P0) @ rng.standard_normal(6)
            x0[4:] = wrap(x0[4:])
        else:
            first = int(np.argmax(valid))
            origin = truth[first]
            dt = np.diff(frame.t, prepend=frame.t[0] - np.median(np.diff(frame.t)))
            model = AUVSonar(Q, R, dt=dt, yaw_rate=self.yaw_rate or 0.0, origin=origin)
            meas = model.h(truth, 0) + rng.standard_normal(truth.shape) @ np.linalg.cholesky(R).T
            meas[:, 1:] = wrap(meas[:, 1:])
            z = np.where(valid[:, None], meas, np.nan)
            z[first] = np.nan  # at the sonar itself the bearing is undefined
            x0 = np.concatenate([origin, [0.0, 0.0, 0.0]])
            P0 = np.diag([1.0, 1.0, 1.0, 4.0, 0.1, np.pi**2]) if P0 is None else P0
        angles = {}
        att = frame.reference.get("attitude")
        if att is not None and att.components == ("pitch", "yaw"):
            angles = {
                "pitch": np.where(att.valid, att.values[:, 0], np.nan),
                "yaw": np.where(att.valid, att.values[:, 1], np.nan),
            }
        inputs = {
            "reference": describe(frame, "position", "reference"),
            "sonar": describe(frame, "sonar")
            if "sonar" in frame.channels
            else "synthesised from the reference with noise R",
        }
        return Problem(
            model,
            z,
            x0,
            P0,
            frame.t,
            truth,
            valid,
            (0, 1, 2),
            ("x", "y", "z"),
            angles,
            {"pitch": 4, "yaw": 5} if angles else {},
            params={"Q": np.diag(Q).tolist(), "R": np.diag(R).tolist()},
            inputs=inputs,
        )
