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

from replay.util.errors import DataError, ReplayError
from replay.models.depth import R_FIXED, DepthModel, paper_Q

from . import Problem, Task

CHANNELS = ("depth", "speed", "pitch")


class DepthTask(Task):
    name = "depth"

    def __init__(self, Q=None, R=None, P0=None, window: int = 50):
        self.Q = None if Q is None else np.asarray(Q, float)
        self.R = R_FIXED.copy() if R is None else np.asarray(R, float)
        self.P0 = None if P0 is None else np.asarray(P0, float)
        self.window = int(window)
        for name, M in (("Q", self.Q), ("R", self.R), ("P0", self.P0)):
            if M is not None and M.shape != (3, 3):
                raise ReplayError(f"task depth: {name} must be 3x3 (got shape {M.shape})")

    def build(self, frame, rng):
        source = frame.meta.get("path") or frame.meta.get("source") or frame.meta.get("dataset")
        columns = frame.meta.get("columns", {})
        z = np.empty((len(frame.t), 3))
        for i, name in enumerate(CHANNELS):
            ch = frame.channels.get(name)
            if ch is None:
                raise DataError(source, f"no {name} sensor column: the depth task needs depth, speed and pitch")
            z[:, i] = np.where(ch.valid, ch.values, np.nan)
            n_ok = int(np.isfinite(z[:, i]).sum())
            if n_ok < self.window:
                raise DataError(source, f"column {columns.get(name, name)}: {n_ok} valid samples, "
                                f"fewer than the noise-estimation window of {self.window}")
        ref = frame.reference.get("depth")
        if ref is None:
            raise DataError(source, "no reference depth column (e.g. ref_depth_m) to score against")
        truth = np.where(ref.valid, ref.values, np.nan)[:, None]
        step = np.diff(frame.t)
        med = float(np.median(step)) if len(step) else float(frame.meta.get("dt", 0.05))
        uniform = len(step) == 0 or float(step.max() - step.min()) <= 1e-6 * med
        dt = med if uniform else np.concatenate([[med], step])
        Q = paper_Q()[0] if self.Q is None else self.Q
        model = DepthModel(Q, self.R, dt)
        first = np.isfinite(z).all(axis=1)
        x0 = np.nan_to_num(z[int(np.argmax(first))] if first.any() else z[0])
        P0 = self.R if self.P0 is None else self.P0
        angles, extra = {}, {}
        if "pitch" in frame.reference:
            p = frame.reference["pitch"]
            angles["pitch"] = np.where(p.valid, p.values, np.nan)
        if "speed" in frame.reference:
            s = frame.reference["speed"]
            extra["speed"] = (np.where(s.valid, s.values, np.nan), 1)
        return Problem(model, z, x0, P0, frame.t, truth, ref.valid.copy(), (0,), ("depth",),
                       angles, {"pitch": 2} if angles else {},
                       params={"Q": Q.tolist(), "Q_source": paper_Q()[1] if self.Q is None else "user",
                               "R": self.R.tolist(), "T": med},
                       truth_extra=extra)
