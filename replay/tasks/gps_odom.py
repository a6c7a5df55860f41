"""``gps-odom``: 2-D position from wheel odometry, a gyro and a thinned GPS fix track.

For ground robots recorded as ROS bags (e.g. robot_localization's ``test1.bag``:
Husky odometry, IMU, NavSatFix), where no ground truth exists.

**Reference.** The reference is the frame's ``position`` reference channel. When
it is the same topic as the ``gps`` channel (the usual case: the fix track is
the only external position), the fixes are split: every ``gps_every``-th valid
fix (the 0th, the gps_every-th, ...) is given to the filters as a measurement,
and the other fixes, never seen by any filter, are the reference the scorer
uses. So the score is the error at the held-out fixes (the fix noise, about
1 m for test1.bag, is part of it). When the reference is another topic, it is
scored wherever valid and the thinned fixes are still the only GPS input.

**Model** (:class:`UnicycleModel`, constant turn rate and velocity): state
``x = [east, north, heading, v, omega]`` (heading: 0 = east, counter-clockwise
positive, wrapped), one filter step per frame sample with dt_k = t_k - t_{k-1}::

    east_k  = east + v cos(heading) dt      heading_k = heading + omega dt
    north_k = north + v sin(heading) dt     v_k = v,  omega_k = omega

    Q_k = diag(q_pos, q_pos, q_heading, q_v, q_omega) * dt

Measurements ``z = [east, north, v, omega, omega]``: the fed GPS fix (ENU),
the odometry forward speed (twist.linear.x in the base frame) and yaw rate
(twist.angular.z), and the IMU yaw rate (angular_velocity.z); NaN where the
sample has no such message. R = diag(r_gps, r_gps, r_v, r_omega, r_gyro).

**Prior.** At the first fed fix, heading from the first fed fix at least 2 m
from it (measurements only, never the reference), v = omega = 0;
P0 = diag(r_gps, r_gps, p0_heading, p0_v, p0_omega).

Noise defaults: r_gps = 1 m^2 (test1.bag's reported fix covariance), r_gyro
= 0.01 (rad/s)^2; skid-steer wheel odometry is poor on turns, hence r_v = 0.04
(m/s)^2, r_omega = 0.1 (rad/s)^2, and q_heading = 0.01 rad^2/s. These were set
by looking at the first 60 s of test1.bag (with tighter values the particle
filter collapses onto a wrong heading); they are engineering choices, not a
paper's, and every one is a task parameter.

Inputs are found by **role** (:func:`replay.tasks.role_input`), whatever the
channels are called: ``gps`` (required: a NavSatFix topic, or one declared
``role = "gps"``), ``odometry`` (its forward speed and yaw rate: an Odometry
topic, or a twist declared ``role = "odometry"``) and ``imu`` (its z gyro)
when present. Which channels were used goes into ``Problem.inputs`` (the
manifest's ``task_inputs``); without odometry or IMU a note says that the
filters run on the fixes only (``task_notes``). Defaults are plain engineering
choices (no paper prescribes them), written here and in the manifest.
"""

from __future__ import annotations

import numpy as np

from replay.util.angles import wrap
from replay.util.errors import ReplayError
from replay.model import Model
from replay.util.params import Param

from . import Problem, Task, describe, missing, role_input, source_of, why_missing


class UnicycleModel(Model):
    """Constant turn rate and velocity on the frame's (irregular) time axis."""

    nx, nz = 5, 5
    x_angles = (2,)
    z_angles = ()

    def __init__(self, dt, q, r):
        self.dt = np.asarray(dt, float)
        self.q = np.asarray(q, float)
        self.R = np.diag(np.asarray(r, float))
        self.Q = np.diag(self.q * max(float(np.median(self.dt)), 1e-6))
        self._H = np.array([[1, 0, 0, 0, 0], [0, 1, 0, 0, 0], [0, 0, 0, 1, 0], [0, 0, 0, 0, 1], [0, 0, 0, 0, 1]], float)

    def f(self, x, k):
        dt = self.dt[k]
        e, n, th, v, w = np.moveaxis(x, -1, 0)
        return np.stack([e + v * np.cos(th) * dt, n + v * np.sin(th) * dt, wrap(th + w * dt), v, w], axis=-1)

    def F(self, x, k):
        dt = self.dt[k]
        th, v = x[2], x[3]
        J = np.eye(5)
        J[0, 2], J[0, 3] = -v * np.sin(th) * dt, np.cos(th) * dt
        J[1, 2], J[1, 3] = v * np.cos(th) * dt, np.sin(th) * dt
        J[2, 4] = dt
        return J

    def process_cov(self, k):
        return np.diag(self.q * max(self.dt[k], 1e-9))

    def h(self, x, k):
        return x @ self._H.T

    def H(self, x, k):
        return self._H


def _variance(name, default, doc, unit):
    return Param(name, float, default, doc, unit=unit, low=0, low_open=True)


class GpsOdomTask(Task):
    name = "gps-odom"
    LOST_M = 20.0  # lost-track threshold (m): GPS-scale errors; working filters stay near 1-3 m
    PARAMS = (
        Param(
            "gps_every",
            int,
            5,
            "every gps_every-th valid fix is fed to the filters; the others are the held-out reference",
            low=1,
        ),
        _variance("q_pos", 0.01, "process noise of east and north, per second", "m^2/s"),
        _variance("q_heading", 0.01, "process noise of the heading, per second", "rad^2/s"),
        _variance("q_v", 0.5, "process noise of the forward speed, per second", "(m/s)^2/s"),
        _variance("q_omega", 0.5, "process noise of the turn rate, per second", "(rad/s)^2/s"),
        _variance("r_gps", 1.0, "GPS fix noise variance per axis (also the prior's)", "m^2"),
        _variance("r_v", 0.04, "odometry forward-speed noise variance", "(m/s)^2"),
        _variance("r_omega", 0.1, "odometry yaw-rate noise variance", "(rad/s)^2"),
        _variance("r_gyro", 0.01, "IMU yaw-rate noise variance", "(rad/s)^2"),
        _variance("p0_heading", 0.25, "prior variance of the heading", "rad^2"),
        _variance("p0_v", 1.0, "prior variance of the forward speed", "(m/s)^2"),
        _variance("p0_omega", 0.25, "prior variance of the turn rate", "(rad/s)^2"),
    )

    def build(self, frame, rng):
        where = source_of(frame)
        gps_in = role_input(frame, "gps", self.name)
        ref = frame.reference.get("position")
        if gps_in is None or "position" not in gps_in.channels:
            raise missing(
                frame,
                self.name,
                "a gps input (a NavSatFix topic, or a topic with role = \"gps\" in the mapping; docs/bags.md)",
                ("gps", "gps_position"),
            )
        gps_name = gps_in.channels["position"]
        gps = frame.channels[gps_name]
        if ref is None:
            raise missing(
                frame,
                self.name,
                "a position reference ([reference] position in the mapping; docs/bags.md)",
                ("position",),
            )
        n = len(frame.t)
        idx = np.flatnonzero(gps.valid)
        if len(idx) < 2:
            raise ReplayError(
                f"{where}: task gps-odom needs at least 2 valid fixes on {gps_name} (got {len(idx)})"
                + (f"; {why}" if (why := why_missing(frame, (gps_name,))) else "")
            )
        fed = np.zeros(n, bool)
        fed[idx[:: self.gps_every]] = True
        z = np.full((n, 5), np.nan)
        z[fed, :2] = gps.values[fed, :2]
        inputs = {"gps": describe(frame, gps_name), "reference": describe(frame, "position", "reference")}
        absent = []
        for role, fields in (("odometry", ((2, "velocity", 0), (3, "rate", 2))), ("imu", ((4, "gyro", 2),))):
            found = role_input(frame, role, self.name)
            used = []
            for col, fname, comp in fields:
                name = (found.channels if found else {}).get(fname)
                ch = frame.channels.get(name) if name else None
                if ch is None or ch.width <= comp:
                    continue
                ok = ch.valid & np.isfinite(ch.values.reshape(n, -1)[:, comp])
                if ok.any():
                    z[ok, col] = ch.values.reshape(n, -1)[ok, comp]
                    used.append(name)
                    inputs[f"{role}_{fname}"] = describe(frame, name)
            if not used:
                absent.append(role if found is None else f"{role} ({found.entry}: no valid sample)")
        notes = []
        if len(absent) == 2:
            notes.append(
                f"task gps-odom: no {absent[0]} and no {absent[1]} input (roles odometry, imu; "
                "docs/bags.md): the filters use the GPS fixes only"
            )
        elif absent:
            notes.append(
                f"task gps-odom: no {absent[0]} input (docs/bags.md): the filters use the GPS fixes "
                f"and the {'imu' if absent[0].startswith('odometry') else 'odometry'} only"
            )
        truth = ref.values[:, :2]
        valid = ref.valid.copy()
        holdout = ref.description == gps.description
        if holdout:
            valid &= ~fed
        dt = np.diff(frame.t, prepend=frame.t[0])
        model = UnicycleModel(
            dt,
            [self.q_pos, self.q_pos, self.q_heading, self.q_v, self.q_omega],
            [self.r_gps, self.r_gps, self.r_v, self.r_omega, self.r_gyro],
        )
        fed_idx = np.flatnonzero(fed)
        p_first = gps.values[fed_idx[0], :2]
        far = [i for i in fed_idx if np.hypot(*(gps.values[i, :2] - p_first)) >= 2.0]
        d = gps.values[far[0], :2] - p_first if far else np.array([1.0, 0.0])
        x0 = np.array([p_first[0], p_first[1], np.arctan2(d[1], d[0]), 0.0, 0.0])
        P0 = np.diag([self.r_gps, self.r_gps, self.p0_heading, self.p0_v, self.p0_omega])
        return Problem(
            model,
            z,
            x0,
            P0,
            frame.t,
            truth,
            valid,
            (0, 1),
            ("x", "y"),
            params=dict(self.params(), fed_fixes=int(fed.sum()), holdout=bool(holdout)),
            inputs=inputs,
            notes=notes,
        )
