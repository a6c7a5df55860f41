"""``depth``: depth, speed and pitch of a maneuvering AUV from its own sensors (paper 000).

State [z, v, phi] (:class:`replay.models.depth.DepthModel`, eq. 4), measurement
= the frame's ``depth``, ``speed`` and ``pitch`` sensor channels (eq. 6; masked
samples are NaN, so a filter updates with what is there). Scored against the
frame's reference: ``depth`` as the position (``depth_rmse``), ``pitch`` as an
angle (``pitch_rmse``) and ``speed`` (``speed_rmse``) where the reference has them.

* T: the frame's step; a jittered time axis gives one T per step (T[0] = the
  median step).
* Q: the paper's (:func:`replay.models.depth.paper_Q`: the printed matrix is
  not positive definite, so diag(0.2^2, 1^2, 0.5^2)); R: the paper's fixed
  R = diag(0.2^2, 5^2, 0.5^2) used by EKF and MMPF (GPF estimates its own).
* Prior (not in the paper): x0 = the first sensor sample (0 for a missing
  component), P0 = the fixed R.
* ``window`` (default 50, the paper's wavelet window): a log with fewer valid
  samples in a channel is refused, naming the file and the column.
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import DataError
from replay.util.params import Param
from replay.models.depth import R_FIXED, DepthModel, paper_Q
from replay.models.noise import Covariance, as_matrix, diagonal

from . import Problem, Task, describe, why_missing

CHANNELS = ("depth", "speed", "pitch")
UNITS = "m^2, (m/s)^2, rad^2"


class DepthTask(Task):
    name = "depth"
    LOST_M = 1.0  # lost-track threshold (m): depth sensor noise 0.05-0.2 m; working filters stay near 0.1 m
    PARAMS = (
        Covariance(
            "Q",
            list,
            None,
            "process noise covariance of [z, v, phi]; null = the paper's, made "
            "positive definite (replay.models.depth.paper_Q)",
            unit=UNITS,
            dim=3,
            optional=True,
        ),
        Covariance(
            "R",
            list,
            diagonal(R_FIXED),
            "fixed measurement noise covariance (000: used by EKF and MMPF)",
            unit=UNITS,
            dim=3,
        ),
        Covariance("P0", list, None, "prior covariance; null = R", unit=UNITS, dim=3, optional=True),
        Param("window", int, 50, "noise-estimation window: fewer valid samples in a channel are refused", low=1),
    )

    def build(self, frame, rng):
        Qgiven, R, P0given = as_matrix(self.Q), as_matrix(self.R), as_matrix(self.P0)
        source = frame.meta.get("path") or frame.meta.get("source") or frame.meta.get("dataset")
        columns = {name: cols[0] for name, cols in frame.columns.items() if cols}
        z = np.empty((len(frame.t), 3))
        for i, name in enumerate(CHANNELS):
            ch = frame.channels.get(name)
            col = columns.get(name, name)
            if ch is None:
                why = why_missing(frame, (name, col))
                raise DataError(
                    source,
                    f"no {name} sensor column: the depth task needs depth, speed and pitch"
                    + (f" ({why})" if why else ""),
                )
            z[:, i] = np.where(ch.valid, ch.values, np.nan)
            n_ok = int(np.isfinite(z[:, i]).sum())
            if n_ok < self.window:
                why = why_missing(frame, (name, col))
                raise DataError(
                    source,
                    f"column {col}: {n_ok} valid samples, "
                    f"fewer than the noise-estimation window of {self.window}" + (f"; {why}" if why else ""),
                )
        ref = frame.reference.get("depth")
        if ref is None:
            raise DataError(source, "no reference depth column (e.g. ref_depth_m) to score against")
        if not ref.valid.any():
            why = why_missing(frame, ("reference depth", columns.get("reference depth", "ref_depth")))
            raise DataError(source, "no valid reference depth sample to score against" + (f" ({why})" if why else ""))
        truth = np.where(ref.valid, ref.values, np.nan)[:, None]
        step = np.diff(frame.t)
        med = float(np.median(step)) if len(step) else float(getattr(frame.simulation, "dt", None) or 0.05)
        uniform = len(step) == 0 or float(step.max() - step.min()) <= 1e-6 * med
        dt = med if uniform else np.concatenate([[med], step])
        Q = paper_Q()[0] if Qgiven is None else Qgiven
        model = DepthModel(Q, R, dt)
        first = np.isfinite(z).all(axis=1)
        x0 = np.nan_to_num(z[int(np.argmax(first))] if first.any() else z[0])
        P0 = R if P0given is None else P0given
        angles, extra = {}, {}
        if "pitch" in frame.reference:
            p = frame.reference["pitch"]
            angles["pitch"] = np.where(p.valid, p.values, np.nan)
        if "speed" in frame.reference:
            s = frame.reference["speed"]
            extra["speed"] = (np.where(s.valid, s.values, np.nan), 1)
        return Problem(
            model,
            z,
            x0,
            P0,
            frame.t,
            truth,
            ref.valid.copy(),
            (0,),
            ("depth",),
            angles,
            {"pitch": 2} if angles else {},
            params={"Q": Q.tolist(), "Q_source": paper_Q()[1] if Qgiven is None else "user", "R": R.tolist(), "T": med},
            truth_extra=extra,
            extra_units={"speed": "m/s"},
            inputs={
                **{n: describe(frame, n) for n in CHANNELS},
                **{f"reference {n}": describe(frame, n, "reference") for n in frame.reference},
            },
        )
