"""``dead-reckoning``: paper 001's small-AUV navigation (model :mod:`replay.models.sauv`).

The filter state is in north-east-down (NED); the frame's ENU reference is
converted for scoring (axes ``north, east, depth`` — or ``north, east`` when the
reference is 2-D). Roll and pitch from the frame's ``attitude`` channel are
the model's inputs; the heading is a measurement. Attitude channels follow the
Bohai adapter's convention (roll positive left side up, pitch positive front
down, yaw 0 = east counter-clockwise), converted here: NED pitch = −pitch,
NED heading = π/2 − yaw, roll unchanged.

* **DVL frame** (``dvl_velocity`` present, e.g. ``sim/sauv-current``): the
  paper's measurement (eq. 3), z = [depth, v_b, a_b, heading]; no position
  fix at all (pure dead reckoning); prior: the simulator's initial state,
  drawn once with P0 from the task's seed.
* **Bohai frame** (no DVL: the adapter drops the logged velocities as
  implausible): z = [north, east, v_yb, v_zb, a_b, heading], where north/east are
  the fresh GPS fixes (``gps_position`` valid only when a new fix arrived,
  i.e. at the surface) with ``gps_sigma`` m, and v_yb = v_zb = 0 are
  pseudo-measurements (a torpedo AUV does not slip sideways or heave in its
  body frame; ``pseudo_sigma`` m/s), and so is a_b = 0 (``accel_sigma``
  m/s²: the log's accelerations are dropped or include gravity, and an
  unobserved random-walk acceleration integrates to kilometres over a
  10-minute dive). Forward speed is *estimated* from the fixes. Depth is not measured (the Bohai ``depth`` column is
  all zero) and not scored. **The reference** is the vehicle's own navigation
  solution (``lat``/``lon`` columns, an INS/DVL/GPS product of unknown
  quality, with jumps masked by the adapter), not ground truth.
  With ``score="fixes"`` the reference is instead the **first fresh GPS fix
  after each dive** (a gap of more than ``dive_gap`` s between fixes): that
  fix is withheld from the filter and the RMSE is the position error at the
  resurfacing fixes.
"""

from __future__ import annotations

import numpy as np

from replay.util.angles import wrap
from replay.util.params import Param
from replay.models.sauv import COMPONENTS, DEG, PAPER_MEASURED, SAUV, Q_DEFAULT
from replay.models.noise import Covariance, as_matrix

from . import Problem, Task, describe, missing, simulated_start

BOHAI_MEASURED = (0, 1, 4, 5, 6, 7, 8, 9)


def ned_attitude(att):
    """(roll, pitch, heading) in NED from an adapter-convention attitude channel (n, 3)."""
    return att[:, 0], -att[:, 1], wrap(np.pi / 2 - att[:, 2])


class DeadReckoningTask(Task):
    name = "dead-reckoning"
    LOST_M = 1000.0  # lost-track threshold (m): dead reckoning drifts by hundreds of metres over the mission by design

    PARAMS = (
        Covariance(
            "Q",
            list,
            None,
            "process noise covariance of the 10 states; null = the model's, scaled by the frame's step / 0.5 s",
            dim=10,
            optional=True,
        ),
        Covariance(
            "R",
            list,
            None,
            "measurement noise covariance (DVL frame: depth, body velocity, "
            "acceleration, heading; Bohai frame: north, east, pseudo-measurements, heading); null = from "
            "the sigmas below",
            dim=8,
            optional=True,
        ),
        Covariance("P0", list, None, "prior covariance of the 10 states; null = the task's", dim=10, optional=True),
        Param(
            "gps_sigma", float, 5.0, "GPS fix noise standard deviation (Bohai frames)", unit="m", low=0, low_open=True
        ),
        Param(
            "pseudo_sigma",
            float,
            0.05,
            "standard deviation of the zero sideways/heave pseudo-measurements",
            unit="m/s",
            low=0,
            low_open=True,
        ),
        Param(
            "accel_sigma",
            float,
            0.05,
            "standard deviation of the zero-acceleration pseudo-measurements",
            unit="m/s^2",
            low=0,
            low_open=True,
        ),
        Param(
            "score",
            str,
            "navigation",
            "reference: the vehicle's navigation solution, or the first fix after each dive",
            choices=("navigation", "fixes"),
        ),
        Param(
            "dive_gap", float, 10.0, "a gap between fixes longer than this is a dive", unit="s", low=0, low_open=True
        ),
        Param(
            "mean_maneuver",
            str,
            "previous",
            "mean manoeuvre of the model (replay.models.sauv)",
            choices=("previous", "zero"),
        ),
    )

    def build(self, frame, rng):
        att = frame.channels.get("attitude")
        if att is None or att.width != 3:
            raise missing(frame, self.name, "an attitude channel [roll, pitch, yaw]", ("attitude",))
        if not att.valid.any():
            raise missing(frame, self.name, "a valid attitude sample (every one is masked)", ("attitude",))
        roll, pitch, heading = ned_attitude(np.where(att.valid[:, None], att.values, 0.0))
        heading = np.where(att.valid, heading, np.nan)
        dt = np.diff(frame.t, prepend=frame.t[0] - (np.median(np.diff(frame.t)) if len(frame.t) > 1 else 1.0))
        Q = as_matrix(self.Q)
        if Q is None:
            Q = Q_DEFAULT * (float(np.median(dt)) / 0.5)
        if "dvl_velocity" in frame.channels:
            return self._dvl(frame, rng, dt, roll, pitch, heading, Q)
        return self._bohai(frame, dt, roll, pitch, heading, Q)

    def _dvl(self, frame, rng, dt, roll, pitch, heading, Q):
        ch = frame.channels
        cols = [np.where(ch["depth"].valid, ch["depth"].values, np.nan)]
        for name in ("dvl_velocity", "accel"):
            c = ch[name]
            cols += list(np.where(c.valid[:, None], c.values, np.nan).T)
        z = np.column_stack(cols + [heading])
        model = SAUV(
            dt, pitch, roll, Q=Q, R=as_matrix(self.R), measured=PAPER_MEASURED, mean_maneuver=self.mean_maneuver
        )
        ref = frame.reference["position"]
        truth = np.column_stack([ref.values[:, 1], ref.values[:, 0], -ref.values[:, 2]])
        P0 = (
            np.diag([1.0, 1.0, 1.0] + [0.05**2] * 3 + [0.02**2] * 3 + [(2 * DEG) ** 2])
            if self.P0 is None
            else as_matrix(self.P0)
        )
        x_true0 = simulated_start(frame, COMPONENTS, self.name)
        x0 = x_true0 + np.linalg.cholesky(P0) @ rng.standard_normal(10)
        x0[9] = wrap(x0[9])
        pb = Problem(
            model,
            z,
            x0,
            P0,
            frame.t,
            truth,
            ref.valid.copy(),
            (0, 1, 2),
            ("north", "east", "depth"),
            params=self.params(),
            inputs={name: describe(frame, name) for name in ("depth", "dvl_velocity", "accel", "attitude")},
        )
        extra, units = {}, {}  # body velocity and acceleration, scored as extra components when present
        for name, first in (("velocity_body", 3), ("accel_body", 6)):
            if name in frame.reference:
                c = frame.reference[name]
                for j, comp in enumerate(c.components):
                    extra[comp] = (np.where(c.valid, c.values[:, j], np.nan), first + j)
                    units[comp] = c.unit
        pb.truth_extra, pb.extra_units = extra, units
        return pb

    def _bohai(self, frame, dt, roll, pitch, heading, Q):
        gps = frame.channels.get("gps_position")
        ref = frame.reference.get("position")
        if gps is None:
            raise missing(
                frame, self.name, "a DVL channel, or gps_position fixes (columns lat_gps, lon_gps)", ("gps_position",)
            )
        if ref is None:
            raise missing(frame, self.name, "a reference position", ("position",))
        n = len(frame.t)
        fix = gps.valid.copy()
        ne = np.column_stack([gps.values[:, 1], gps.values[:, 0]])
        truth = np.column_stack([ref.values[:, 1], ref.values[:, 0]])
        valid = ref.valid.copy()
        idx = np.flatnonzero(fix)
        resurface = idx[1:][np.diff(frame.t[idx]) > self.dive_gap] if len(idx) > 1 else idx[:0]
        if self.score == "fixes":
            truth = np.where(fix[:, None], ne, np.nan)
            valid = np.zeros(n, bool)
            valid[resurface] = True
            fix[resurface] = False  # withheld from the filter: it is the reference there
        z = np.full((n, 8), np.nan)
        z[fix, :2] = ne[fix]
        z[:, 2:7] = 0.0
        z[:, 7] = heading
        R = (
            np.diag([self.gps_sigma**2] * 2 + [self.pseudo_sigma**2] * 2 + [self.accel_sigma**2] * 3 + [(2 * DEG) ** 2])
            if self.R is None
            else as_matrix(self.R)
        )
        model = SAUV(dt, pitch, roll, Q=Q, R=R, measured=BOHAI_MEASURED, mean_maneuver=self.mean_maneuver)
        first = idx[0] if len(idx) else int(np.argmax(ref.valid))
        start = ne[first] if len(idx) else truth[first]
        x0 = np.zeros(10)
        x0[:2] = start
        x0[9] = heading[first] if np.isfinite(heading[first]) else 0.0
        P0 = (
            np.diag([self.gps_sigma**2] * 2 + [1.0, 1.0, 0.1, 0.1, 0.1, 0.1, 0.1, (5 * DEG) ** 2])
            if self.P0 is None
            else as_matrix(self.P0)
        )
        params = dict(self.params(), resurfacing_fixes=int(len(resurface)), fixes_used=int(fix.sum()))
        inputs = {
            "attitude": describe(frame, "attitude"),
            "gps": describe(frame, "gps_position"),
            "reference": describe(frame, "position", "reference"),
        }
        problem = Problem(
            model, z, x0, P0, frame.t, truth, valid, (0, 1), ("north", "east"), params=params, inputs=inputs
        )
        if self.score == "fixes":  # the reference is the GPS itself (replay/scoring/provenance.py)
            problem.reference_provenance = {
                "kind": "fed sensor",
                "source": "the first GPS fix after each dive, withheld from the filters",
                "built_from": {"gps_position": "the same GPS: its other fixes are fed"},
                "compared": "each filter's error at the resurfacing fixes it was not given: the drift over "
                "each dive, measured by the GPS (its own error included)",
            }
        return problem
