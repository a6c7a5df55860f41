"""``fusion``: the recording's own sensors, fused by a kinematic model — no synthetic measurement.

What robot_localization's ``ekf_localization_node`` does on a robot, run offline with every filter of ``replay``
and scored against the recording's reference. Configured by the mapping (``docs/bags.md``, "The fusion task"):

* **State**: 2-D ``[east, north, yaw, u, v, r]`` or 3-D ``[east, north, up, roll, pitch, yaw, u, v, w, p, q,
  r]`` (:mod:`replay.models.kinematic`); ``dims = "auto"`` takes 3-D when the recording has a depth input, else
  2-D. The choice is printed in the notes and recorded.
* **Inputs**: every sensor input of the frame (:mod:`replay.tasks.fusion_inputs`), each field used absolutely or
  differentially, at its own messages' times (the frame's time axis is the union of all messages: at a step, the
  components of the messages that arrived there are measured, the others are missing; gaps are predicted
  through).
* **Noise**: the entry's declared ``noise`` where given; else the message's recorded covariance (its diagonal,
  per component and per message: Odometry pose and twist, Imu orientation, angular velocity and linear
  acceleration, PoseWithCovarianceStamped, TwistWithCovarianceStamped, NavSatFix; the ``<entry>_<field>_var``
  channels), a zero, negative, ``-1``-marked or missing entry replaced by the task's default (``r_*``) and
  counted; else that default (:func:`replay.tasks.fusion_inputs.variance`). The notes and the manifest's
  ``task_noise`` say which source every input used and how many were replaced.
* **Gating**: an entry's ``rejection_threshold`` (a Mahalanobis distance, one for every field or a table per
  field) gates each of its fields at every update (:mod:`replay.filters.gating`: the innovation's NIS for the
  Kalman family, the particles' predictive likelihood for the PF); the rejections are counted per filter, run
  and field (the table's notes, the manifest's ``gating``).
* **Reference**: the frame's ``position`` reference, for scoring only. When it is the same topic as a ``gps``
  input (the fix track is the only external position), every ``gps_every``-th fix is fed and the others are held
  out for scoring, as ``gps-odom`` does. With ``score=outages`` the reference is instead the first fix after
  each outage, withheld from every filter (:mod:`replay.tasks.outages`).
* **Prior**: the first fed absolute position (and attitude) where there is one. Without any absolute position
  input (dead reckoning: DVL + IMU + depth, odometry + IMU), nothing fixes the origin: the start position is the
  reference's sample nearest the first sensor message (the known start of a dead-reckoning run, variance
  ``p0_known``), and a note says so; no other reference sample reaches a filter. Before the first sensor message
  the state is held (dt = 0: nothing is known of the motion). Heading: the first attitude measurement, else the
  direction between the first fed fixes at least 2 m apart, else the reference's first attitude (noted; in 3-D
  its roll and pitch too).
* **Frames**: an odometry's twist is the body's (REP 105's child frame) or declared (``twist_frame``):
  :mod:`replay.tasks.fusion_frames`; every decision is a note.
* **Unconstrained angles**: an attitude angle no input measures absolutely, whose declared sd grows past
  :data:`replay.tasks.fusion_heading.SHRINK_LIMIT`: one line on the table and in the manifest
  (``Problem.unconstrained``, the reference's record): the PF's posterior mean lies inside the arc.

Refused in one line: inputs that leave the speed (no velocity, position or differential position) or the heading
(no attitude, rate or position) unconstrained — every filter would carry its prior there and the table rank
priors —, a frame with no sensor input (naming the tasks that would run), no reference (nothing to score
against: how to declare one), an unknown field, a differential field with fewer than two messages.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from replay import roles
from replay.filters.gating import Gates
from replay.models.kinematic import Kinematic2D, Kinematic3D
from replay.util.errors import ReplayError
from replay.util.params import Param

from . import Problem, Task, describe, outages, source_of
from .fusion_frames import heading_source, imu_yaw_sense, lever_arm, mounted, twist_in_body
from .fusion_heading import unconstrained_angles
from .fusion_inputs import (
    configured,
    differential,
    field_channel,
    has_absolute_position,
    inputs,
    threshold,
    unconstrained,
    variance,
)

POS = dict(low=0, low_open=True)


def _spatial_only(entry) -> bool:
    """Whether an input's default fields measure only what a 2-D state lacks (depth): ``dims = auto``
    takes the 3-D state for it."""
    return any(not entry.spec.components(f, 2) for f in entry.spec.fuse)


def beside_fixes(entry, fuse) -> bool:
    """Whether the role's default was narrowed beside absolute positions (an IMU's attitude left out)."""
    default = entry.spec.fuse_beside_fixes
    return default is not None and entry.fuse is None and tuple(fuse) == tuple(default) != entry.spec.fuse


class FusionTask(Task):
    name = "fusion"
    LOST_M = 20.0  # lost-track threshold (m): GPS-scale; dead reckoning is judged by its drift
    # Noise defaults: those of gps-odom (set on the first 60 s of test1.bag: skid-steer odometry,
    # a ground robot's turns), plain engineering choices like them, every one a task parameter.
    PARAMS = (
        Param(
            "dims",
            str,
            "auto",
            "state dimension: 2 (planar), 3, or auto (3 with a depth input)",
            choices=("auto", "2", "3"),
        ),
        Param(
            "gps_every",
            int,
            5,
            "when the reference is a gps input's topic, every gps_every-th fix is fed, "
            "the others are held out for scoring",
            low=1,
        ),
        Param("q_position", float, 0.01, "process noise of each position axis, per second", unit="m^2/s", **POS),
        Param("q_attitude", float, 0.01, "process noise of each attitude angle, per second", unit="rad^2/s", **POS),
        Param("q_velocity", float, 0.5, "process noise of each body velocity, per second", unit="(m/s)^2/s", **POS),
        Param("q_rate", float, 0.5, "process noise of each body rate, per second", unit="(rad/s)^2/s", **POS),
        Param(
            "r_position", float, 1.0, "position measurement variance per axis (default of an input)", unit="m^2", **POS
        ),
        Param("r_attitude", float, 0.01, "attitude measurement variance per angle", unit="rad^2", **POS),
        Param("r_velocity", float, 0.04, "body velocity measurement variance per axis", unit="(m/s)^2", **POS),
        Param(
            "r_rate",
            float,
            0.01,
            "body rate (gyro, odometry twist) measurement variance per axis",
            unit="(rad/s)^2",
            **POS,
        ),
        Param("r_depth", float, 0.01, "depth measurement variance", unit="m^2", **POS),
        Param("p0_position", float, 1.0, "prior variance of each position axis", unit="m^2", **POS),
        Param("p0_attitude", float, 0.25, "prior variance of each attitude angle", unit="rad^2", **POS),
        Param("p0_velocity", float, 1.0, "prior variance of each body velocity", unit="(m/s)^2", **POS),
        Param("p0_rate", float, 0.1, "prior variance of each body rate", unit="(rad/s)^2", **POS),
        Param(
            "p0_known",
            float,
            1e-4,
            "prior variance of a start position axis or heading taken from the "
            "reference (dead reckoning: the known start)",
            unit="m^2 or rad^2",
            **POS,
        ),
    ) + outages.PARAMS

    def build(self, frame, rng):
        where = source_of(frame)
        found = inputs(frame)
        ref = self._require(frame, where, found)
        dims = 3 if self.dims == "3" or (self.dims == "auto" and any(map(_spatial_only, found))) else 2
        t = np.asarray(frame.t, float)
        m = self._measurements(frame, where, found, ref, dims, t)
        missing = unconstrained(m.index, dims)
        if missing:
            raise ReplayError(
                f"{where}: task fusion: no input constrains the {' or the '.join(missing)} (inputs: "
                f"{', '.join(m.used)}): every filter would carry its prior there and the table would rank "
                "priors, not filters; map "
                + " or ".join(
                    ["a velocity input (role velocity: a DVL, an odometry twist)"] * ("speed" in missing)
                    + ["an attitude or gyro input"] * ("heading" in missing)
                    + ["a position input (gps, pose)"]
                )
                + " (docs/bags.md)"
            )
        model_cls, model, first = self._model(dims, t, m)
        nx = len(model_cls.STATE)
        x0, notes, known = self._prior(frame, ref, dims, nx, m.absolute_pos, m.attitude_at, m.notes, first)
        p0 = self._per_state(dims, self.p0_position, self.p0_attitude, self.p0_velocity, self.p0_rate)
        p0[known] = self.p0_known  # the start taken from the reference: known, as dead reckoning assumes
        P0 = np.diag(p0)
        d = 3 if dims == 3 and ref.values.shape[1] >= 3 else 2
        valid_ref = ref.valid & np.isfinite(ref.values[:, :d]).all(axis=1)
        if m.holdout:
            valid_ref &= ~m.fed_gps
        truth, extra = np.asarray(ref.values[:, :d], float), {}
        if self.score == "outages":  # the resurfacing fixes: the only reference (replay.tasks.outages)
            if m.outage is None:
                raise ReplayError(f"{where}: task fusion: score=outages needs a gps position input (its fixes)")
            truth, valid_ref, extra = outages.reference(m.outage, d, len(t), t, where)
        m.used["reference"] = describe(frame, "position", "reference")
        params = dict(self.params(), state=list(model_cls.STATE), holdout=bool(m.holdout), **extra)
        axes = ("x", "y", "z")[:d]
        angle_index = {"yaw": 5 if dims == 3 else 2}
        pb = Problem(
            model,
            m.Z,
            x0,
            P0,
            t,
            truth,
            valid_ref,
            tuple(range(d)),
            axes,
            angle_index=angle_index,
            params=params,
            inputs=m.used,
            notes=notes,
            noise=m.noise,
        )
        if m.outage is not None:
            pb.reference_extent = valid_ref  # the reference exists at the resurfacing fixes only (its scored share)
        pb.unconstrained = unconstrained_angles(model, m.Z, P0, dims, m.used)
        return pb

    @staticmethod
    def _require(frame, where, found):
        """The frame's position reference; refused without a sensor input or a valid reference."""
        if not found:
            raise ReplayError(
                f"{where}: task fusion: no sensor input (roles {', '.join(roles.ROLES)}; docs/bags.md); "
                "tasks that need none: position, sonar (synthetic "
                "measurements from the reference)"
            )
        ref = frame.reference.get("position")
        if ref is None or not ref.valid.any():
            raise ReplayError(
                f"{where}: task fusion: nothing to score against: the recording has no valid "
                "position reference; declare one in the mapping ([reference] position = { topic = "
                "\"/ground_truth\" }, or a GPS, pose or TF topic; docs/bags.md)"
            )
        return ref

    def _measurements(self, frame, where, found, ref, dims, t):
        """Every fused field of every input: measurement columns, their variances and states, notes."""
        m = SimpleNamespace(
            cols=[],
            rows_R=[],
            index=[],
            sign=[],
            z_angles=[],
            used={},
            notes=[f"task fusion: {dims}-D state"],
            fed_gps=None,
            holdout=False,
            outage=None,
            absolute_pos=None,
            attitude_at=None,
            noise={},
            gate_group=[],
            gate_names=[],
            gate_limit=[],
        )
        absolute = has_absolute_position(found)
        ctx = SimpleNamespace(where=where, ref=ref, dims=dims, t=t, n=len(frame.t), found=found, absolute=absolute)
        for entry in found:
            key = f"[channels] {entry.entry}"
            fuse, diff, noise = configured(entry, f"{where}: {key}", absolute)
            if beside_fixes(entry, fuse) and "attitude" in entry.channels:
                m.notes.append(
                    f"task fusion: {key}: attitude not fused beside absolute positions (an IMU's yaw "
                    "is in its own world frame; declare fuse = [\"gyro\", \"attitude\"] if it is ENU)"
                )
            for fld in fuse + diff:
                self._add_field(frame, ctx, m, entry, key, fld, fld in diff, noise)
        if not m.index:
            raise ReplayError(f"{where}: task fusion: none of the inputs has a valid sample")
        return m

    def _add_field(self, frame, ctx, m, entry, key, fld, is_diff, noise):
        """One field of one input into ``m`` (or a note why not); its meaning, mount, frame: its role."""
        where, n, role = ctx.where, ctx.n, entry.spec
        name = field_channel(frame, entry, fld)
        if name is None:
            raise ReplayError(
                f"{where}: {key}: no field {fld!r} in {entry.source} (it has: {', '.join(sorted(entry.channels))})"
            )
        ch = frame.channels[name]
        vals = np.asarray(ch.values, float).reshape(n, -1)
        valid = ch.valid & np.isfinite(vals).all(axis=1)
        label = fld
        if not is_diff and role.field(fld).twist and "nav_msgs/msg/Odometry" in entry.source:
            vals, note = twist_in_body(frame, entry, fld, vals, valid, where, key)  # REP 105, or declared
            valid = valid & np.isfinite(vals).all(axis=1)
            m.notes.append(note)
        if role.mount == "rotation" and role.field(fld).axes and not is_diff:
            vals, note = mounted(entry, fld, vals, key)
            m.notes.append(note)
        arm = entry.lever_arm is not None or entry.recorded_mount is not None
        if role.mount == "lever_arm" and fld == "position" and not is_diff and arm:
            head = heading_source(frame, ctx.found, where, ctx.absolute)  # the antenna's offset turned by it
            vals, valid, note = lever_arm(frame, entry, vals, valid, head, key)
            m.notes += [note] if note else []
        if fld == "attitude" and "gyro" in role.fields and not is_diff:
            m.notes.append(imu_yaw_sense(frame, entry, vals, valid, where, key))
        if is_diff:
            att_name = field_channel(frame, entry, "attitude")
            att = frame.channels[att_name].values if att_name else None
            rows, derived = differential(ctx.t, vals, valid, att, fld, f"{where}: {key}", ctx.dims == 3)
            vals = np.full((n, 3), np.nan)
            vals[rows] = derived
            valid = np.zeros(n, bool)
            valid[rows] = True
            fld = role.field(fld).differential
        if role.holdout and fld == "position" and self.score == "outages":
            if m.outage is not None:
                raise ReplayError(f"{where}: task fusion: score=outages takes one gps position input, not two")
            valid, m.outage = outages.withhold(self, valid, vals, ctx.t, where)
        elif role.holdout and fld == "position" and ctx.ref.description == ch.description:
            idx = np.flatnonzero(valid)
            fed = np.zeros(n, bool)
            fed[idx[:: self.gps_every]] = True
            valid, m.fed_gps, m.holdout = fed, fed, True
        comps = [c for c in role.components(fld, ctx.dims) if c[0] < vals.shape[1]]
        if not comps or not valid.any():
            m.notes.append(
                f"task fusion: {key} {label}: " + ("not used in a 2-D state" if not comps else "no valid sample")
            )
            return
        var, how, m.noise[f"{entry.entry}.{label}"] = variance(
            frame, entry, label, fld, comps, noise, n, valid, getattr(self, role.field(fld).noise)
        )
        limit = threshold(entry, label)
        if limit is not None:
            how += f"; gated at Mahalanobis distance {limit:g}"
        m.gate_names.append(f"{entry.entry}.{label}")
        m.gate_limit.append(np.inf if limit is None else limit)
        for j, (col, state, sgn, ang) in enumerate(comps):
            m.gate_group.append(len(m.gate_names) - 1)
            z = np.where(valid, vals[:, col], np.nan)
            if ang:
                m.z_angles.append(len(m.index))
            m.cols.append(z)
            m.rows_R.append(var[:, j])
            m.index.append(state)
            m.sign.append(sgn)
        m.used[f"{entry.entry}.{label}"] = describe(frame, name) + (" (differential)" if is_diff else "")
        m.notes.append(f"task fusion: {key} {label}" + (" (differential)" if is_diff else "") + f": noise {how}")
        for r in (r for r in frame.report.entries if r.action == "masked" and r.what == name):  # the adapter's
            m.notes.append(f"task fusion: {key} {label}: {r.count} messages not used ({r.reason})")
        if fld == "position" and m.absolute_pos is None:
            m.absolute_pos = (np.flatnonzero(valid)[0], vals, comps, valid)
        if fld == "attitude" and m.attitude_at is None:
            m.attitude_at = (np.flatnonzero(valid)[0], vals, comps)

    def _model(self, dims, t, m):
        """The kinematic model over the measurements (``m.Z`` set), and the step of the first sensor message."""
        m.Z = np.column_stack(m.cols)
        R = np.column_stack(m.rows_R)
        model_cls = Kinematic3D if dims == 3 else Kinematic2D
        dt = np.diff(t, prepend=t[0])
        first = int(np.flatnonzero(np.isfinite(m.Z).any(axis=1))[0])  # the first sensor message
        dt[: first + 1] = 0.0  # before it nothing is known of the motion: the state is held at the start
        q = self._per_state(dims, self.q_position, self.q_attitude, self.q_velocity, self.q_rate)
        model = model_cls(dt, q, m.index, m.sign, m.z_angles, R)
        if np.isfinite(m.gate_limit).any():  # per-sensor outlier gating (replay.filters.gating)
            model.gates = Gates(np.array(m.gate_group, np.int64), np.array(m.gate_limit), tuple(m.gate_names))
        return model_cls, model, first

    @staticmethod
    def _per_state(dims, pos, att, vel, rate):
        return (
            np.array([pos] * 2 + [att] + [vel] * 2 + [rate])
            if dims == 2
            else np.array([pos] * 3 + [att] * 3 + [vel] * 3 + [rate] * 3)
        )

    @staticmethod
    def _nearest_valid(valid, k):
        idx = np.flatnonzero(valid)
        return int(idx[np.argmin(np.abs(idx - k))])

    def _prior(self, frame, ref, dims, nx, absolute_pos, attitude_at, notes, first):
        x0, known = np.zeros(nx), []
        yaw_i = 5 if dims == 3 else 2
        if absolute_pos is not None:
            k, vals, comps, valid = absolute_pos
            for col, state, sgn, _ in comps:
                x0[state] = sgn * vals[k, col]
        else:
            k = self._nearest_valid(ref.valid, first)
            d = min(dims, ref.values.shape[1])
            x0[:d] = ref.values[k, :d]
            known += list(range(d))
            notes = notes + [
                "task fusion: no absolute position input (dead reckoning): the start position is "
                f"the reference's sample nearest the first sensor message (t = {frame.t[k]:.3f} s); "
                "no other reference sample reaches a filter"
            ]
        if attitude_at is not None:
            k, vals, comps = attitude_at
            for col, state, sgn, _ in comps:
                x0[state] = sgn * vals[k, col]
        elif absolute_pos is not None:
            k, vals, comps, valid = absolute_pos
            idx = np.flatnonzero(valid)
            p0 = vals[idx[0], :2]
            far = [i for i in idx if np.hypot(*(vals[i, :2] - p0)) >= 2.0]
            if far:
                d = vals[far[0], :2] - p0
                x0[yaw_i] = np.arctan2(d[1], d[0])
        else:
            att = frame.reference.get("position_attitude")
            if att is not None and att.valid.any():
                k = self._nearest_valid(att.valid, first)
                angles = [yaw_i] if dims == 2 else [3, 4, 5]  # 3-D: roll and pitch too (the known start)
                x0[angles] = att.values[k, 3 - len(angles) : 3]
                known += angles
                notes = notes + [
                    "task fusion: no attitude input: the start "
                    + ("heading" if dims == 2 else "attitude (roll, pitch, yaw)")
                    + " is the reference's (nearest the first sensor message)"
                ]
        return x0, notes, known
