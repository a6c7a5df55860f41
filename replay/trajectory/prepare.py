"""What evo does to two trajectories around their association, as options of ``replay score``.

In evo's order (:func:`replay.trajectory.scoring.score` calls them):

1. :func:`window` (``--t-start``/``--t-end``): only poses stamped in [t_start, t_end] (the estimate's
   stamps with ``t_offset`` added, i.e. on the reference's clock) take part.
2. association; with ``--sync-method interpolation`` (evo's ``SyncMethod.interpolation``) the pairs are
   chosen as by the nearest stamp, then the trajectory with more poses is resampled at the matched
   stamps of the other (:func:`interpolate`: positions linear, orientations slerp, covariance linear),
   so both sides of a pair carry the same instant.
3. :func:`thin` (``--downsample N``: N poses evenly spaced by index, evo's ``downsample``;
   ``--motion-filter DIST ANGLE``: a pose is kept when the path since the last kept pose reaches DIST
   metres or its rotation from it reaches ANGLE degrees, evo's ``motion_filter``). The kept indices
   are chosen on the reference and applied to both sides, so every pair stays a pair (evo filters
   each side on its own, which can unpair them).
4. alignment (:mod:`replay.scoring.align`), then :func:`project` (``--project-to-plane xy|xz|yz``,
   after the alignment as in evo): the dropped axis set to 0 and each orientation reduced to its
   rotation about the plane's normal (the twist of a swing-twist decomposition).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from replay.trajectory import quat
from replay.trajectory.base import Trajectory
from replay.util.errors import ReplayError

SYNC_METHODS = ("nearest", "interpolation")
PLANES = {"xy": 2, "xz": 1, "yz": 0}  # the plane -> the index of the axis it drops


def window(tr: Trajectory, t_start, t_end, offset: float = 0.0) -> Trajectory:
    """The poses of ``tr`` whose stamp + ``offset`` lies in [t_start, t_end] (None: open)."""
    if t_start is None and t_end is None:
        return tr
    t = tr.t + offset
    keep = np.ones(len(t), bool)
    if t_start is not None:
        keep &= t >= t_start
    if t_end is not None:
        keep &= t <= t_end
    if keep.sum() < 2:
        raise ReplayError(
            f"{tr.source or tr.name}: {int(keep.sum())} pose(s) between t_start {t_start} and t_end "
            f"{t_end} s (its stamps {t[0]:.3f} .. {t[-1]:.3f} s): at least 2 are needed"
        )
    return tr.take(keep)


def interpolate(tr: Trajectory, t) -> Trajectory:
    """``tr`` resampled at the stamps ``t`` (within its span up to the association tolerance: clamped)."""
    t = np.asarray(t, float)
    k = np.clip(np.searchsorted(tr.t, t, side="right") - 1, 0, len(tr.t) - 2)
    f = np.clip((t - tr.t[k]) / (tr.t[k + 1] - tr.t[k]), 0.0, 1.0)
    p = tr.p[k] + f[:, None] * (tr.p[k + 1] - tr.p[k])
    q = None if tr.q is None else quat.slerp(tr.q[k], tr.q[k + 1], f)
    cov = None if tr.cov is None else tr.cov[k] + f[:, None, None] * (tr.cov[k + 1] - tr.cov[k])
    return replace(tr, t=t, p=p, q=q, cov=cov, ns=None)


def thin(ref: Trajectory, downsample: int | None = None, motion_filter=None) -> np.ndarray:
    """Indices of the matched poses kept by ``downsample`` and ``motion_filter`` (module docstring)."""
    ids = np.arange(len(ref.t))
    if downsample is not None:
        if downsample < 2:
            raise ReplayError(f"downsample {downsample}: keep at least 2 poses")
        if downsample < len(ids):
            ids = np.unique(np.linspace(0, len(ids) - 1, downsample).astype(int))
    if motion_filter is not None:
        distance, angle_deg = (float(v) for v in motion_filter)
        if not (distance >= 0 and 0 <= angle_deg <= 180):
            raise ReplayError(
                f"motion_filter ({distance:g} m, {angle_deg:g} deg): expected a distance >= 0 m and an "
                "angle in [0, 180] deg"
            )
        ids = ids[_moving(ref.take(ids), distance, np.deg2rad(angle_deg))]
    if len(ids) < 3:
        raise ReplayError(
            f"{ref.source or ref.name}: {len(ids)} matched pose(s) left after downsample/motion_filter; "
            "at least 3 are needed"
        )
    return ids


def _moving(tr: Trajectory, distance: float, angle: float) -> np.ndarray:
    step = np.r_[0.0, np.linalg.norm(np.diff(tr.p, axis=0), axis=1)]
    keep, path, last = [0], 0.0, 0
    for i in range(1, len(tr.t)):
        path += step[i]
        turned = tr.q is not None and quat.angle(quat.multiply(quat.conjugate(tr.q[last]), tr.q[i])) >= angle
        if path >= distance or turned:
            keep.append(i)
            path, last = 0.0, i
    return np.asarray(keep)


def project(tr: Trajectory, plane: str | None) -> Trajectory:
    """``tr`` projected onto ``plane`` (module docstring); None: unchanged."""
    if plane is None:
        return tr
    if plane not in PLANES:
        raise ReplayError(f"project_to_plane {plane!r}: expected one of {', '.join(PLANES)}")
    axis = PLANES[plane]
    p = tr.p.copy()
    p[:, axis] = 0.0
    q = None
    if tr.q is not None:  # the twist about the normal: (w, v . n n) normalised; x, y, z, w order
        q = np.zeros_like(tr.q)
        q[:, axis], q[:, 3] = tr.q[:, axis], tr.q[:, 3]
        q = quat.normalize(np.where(np.linalg.norm(q, axis=1, keepdims=True) > 0, q, [0.0, 0.0, 0.0, 1.0]))
    return replace(tr, p=p, q=q, cov=None)  # no NEES of a projection: its dropped axis has no error
