"""Score an estimated trajectory against a reference: association, alignment, APE/RPE, row metrics.

:func:`score` runs, in evo's order: time association
(:func:`replay.trajectory.associate.associate`), alignment of the matched estimate onto the
matched reference (:func:`replay.scoring.align.align`: ``none``, ``yaw``, ``se3``, ``sim3`` or
``scale``, fitted on the first ``n_to_align`` pairs; or origin alignment, which excludes the
others as in evo), then the APE for each pose relation and, when ``delta`` is given, the RPE
(:mod:`replay.trajectory.pose_error`).

:func:`row_metrics` turns a result into leaderboard cells with the meaning they have for the
offline filters (:mod:`replay.scoring.summary`, one run): ``pos_rmse``, ``x_rmse``..``z_rmse``,
``final_err``, ``drift_pct``, ``nees`` and ``lost`` of the **aligned** estimate (matched poses; the
covariance rotated into the aligned frame, c² R P Rᵀ), ``ate`` = translation APE RMSE after the
alignment, and, when an alignment moved the estimate, ``pos_rmse_unaligned``, ``nees_unaligned`` and
``lost_unaligned`` of the estimate as recorded; and beside
them evo's statistics ``ape_<relation>_<stat>``, ``rpe_<relation>_<stat>``, per-axis RMSE after
alignment ``ape_x_rmse``.., ``rpe_drift_pct`` (mean over pairs of the RPE translation as % of
the reference path length of the pair), ``matched``, ``scale`` (Sim(3)/scale alignment).
Where the estimate records a covariance, ``nees`` is the mean position NEES e' P^-1 e over
matched poses and ``anees*`` its 95 % chi-square(3) band and share of poses inside
(:func:`replay.scoring.metrics.consistency`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from replay.scoring import align as alignment
from replay.scoring import metrics
from replay.trajectory import lengths as by_length
from replay.trajectory import pose_error, prepare, quat
from replay.trajectory.associate import T_MAX_DIFF, associate
from replay.trajectory.base import Trajectory
from replay.util.errors import ReplayError


@dataclass
class Score:
    reference: Trajectory  # matched poses
    estimate: Trajectory  # matched poses, as recorded
    aligned: Trajectory  # matched poses after alignment
    transform: tuple  # (R, t, c) applied to the estimate
    options: dict
    ape: dict = field(default_factory=dict)  # relation -> errors (n,)
    ape_axes: np.ndarray | None = None  # (n, 3) after alignment
    rpe: dict = field(default_factory=dict)  # relation -> errors
    rpe_pairs: tuple | None = None  # (i, j)
    rpe_axes: np.ndarray | None = None
    unmatched: int = 0  # estimate poses left without a reference pose
    lengths: dict = field(default_factory=dict)  # label -> relative errors over a length (trajectory.lengths)

    def stats(self, kind: str = "ape", relation: str = "trans") -> dict:
        return pose_error.statistics((self.ape if kind == "ape" else self.rpe)[relation])


def _align(ref: Trajectory, est: Trajectory, method: str, n_to_align, origin: bool):
    if origin and method not in ("none", "scale"):
        raise ReplayError(f"origin alignment and {method} alignment exclude each other (as in evo): choose one")
    R, t, c = alignment.align(est.p, ref.p, method, n_to_align=n_to_align, strict=method != "none")
    moved = est.transformed(R, t, c) if method != "none" else est
    if origin:
        if moved.q is not None and ref.q is not None:
            R0, t0, _ = alignment.origin(quat.to_matrix(moved.q[0]), moved.p[0], quat.to_matrix(ref.q[0]), ref.p[0])
        else:
            R0, t0 = np.eye(3), ref.p[0] - moved.p[0]
        moved = moved.transformed(R0, t0)
        R, t, c = R0 @ R, R0 @ t + t0, c
    return moved, (R, t, c)


@dataclass(frozen=True)
class Settings:
    """The keyword arguments of :func:`score`, one record (:meth:`replay.trajectory.score_options.ScoreOptions.settings`
    gives them; the defaults are evo's): alignment (``align``, ``n_to_align``, ``align_origin``), association
    (``t_max_diff``, ``t_offset``, ``sync_method``), the pose ``relations``, the RPE (``delta``: None for none,
    ``delta_unit``, ``all_pairs``, ``rel_tol``, ``pairs_from_reference``), the relative errors over ``lengths``
    and evo's trajectory options (:mod:`replay.trajectory.prepare`)."""

    align: str = "none"
    n_to_align: int | None = None
    align_origin: bool = False
    t_max_diff: float = T_MAX_DIFF
    t_offset: float = 0.0
    relations: tuple | list = ("trans",)
    delta: float | None = None
    delta_unit: str = "f"
    all_pairs: bool = False
    rel_tol: float = 0.1
    pairs_from_reference: bool = False
    lengths: str | list | None = None
    lengths_method: str = "rpg"
    sync_method: str = "nearest"
    t_start: float | None = None
    t_end: float | None = None
    downsample: int | None = None
    motion_filter: tuple | list | None = None
    project_to_plane: str | None = None


def score(ref: Trajectory, est: Trajectory, **settings) -> Score:
    """Associate, align and compute the APE (and the RPE when ``delta`` is given); module docstring and
    :mod:`replay.trajectory.prepare` (time window, interpolation, downsampling, motion filter, projection).
    ``settings``: the fields of :class:`Settings` (one record; an unknown name is a TypeError)."""
    o = Settings(**settings)
    relations = [pose_error.relation(r) for r in o.relations]
    _require_orientations(ref, est, relations, o.delta, o.delta_unit)
    if o.sync_method not in prepare.SYNC_METHODS:
        raise ReplayError(f"sync_method {o.sync_method!r}: expected one of {', '.join(prepare.SYNC_METHODS)}")
    ref, est = prepare.window(ref, o.t_start, o.t_end), prepare.window(est, o.t_start, o.t_end, o.t_offset)
    i_est, r, e = _matched(ref, est, o)
    moved, transform = _align(r, e, o.align, o.n_to_align, o.align_origin)
    if o.project_to_plane is not None:  # after the alignment, as evo
        r, e, moved = (prepare.project(x, o.project_to_plane) for x in (r, e, moved))
    options = dict({f.name: getattr(o, f.name) for f in fields(o)}, relations=relations)
    out = Score(r, e, moved, transform, options, unmatched=len(est) - len(np.unique(i_est)))
    for rel in relations:
        if rel != "point_distance_error_ratio":
            out.ape[rel] = pose_error.ape(p_ref=r.p, q_ref=r.q, p_est=moved.p, q_est=moved.q, relation=rel)
    out.ape_axes = pose_error.ape_axes(p_ref=r.p, p_est=moved.p)
    if o.delta is not None:
        _add_rpe(out, relations, o)
    if o.lengths:
        out.lengths = _by_length(ref, r, e, o.lengths, o.lengths_method, scale=float(transform[2]))
    return out


def _require_orientations(ref: Trajectory, est: Trajectory, relations, delta, delta_unit) -> None:
    """Refuse relations (and RPE deltas) that need orientations when a trajectory has positions only."""
    for tr in (ref, est):
        if tr.q is None:
            need = [f"APE {r}" for r in relations if r in pose_error.ROTATION_RELATIONS]
            if delta is not None:
                need += [f"RPE {r}" for r in relations if r in pose_error.RPE_NEEDS_ORIENTATION]
                need += [f"an RPE delta in {delta_unit}"] if delta_unit in ("d", "r") else []
            if need:
                raise ReplayError(
                    f"{tr.source or tr.name}: positions only (no orientation), and {need[0]} needs "
                    "orientations: use -r trans for the APE and -r point_distance for the RPE"
                )


def _matched(ref: Trajectory, est: Trajectory, o: Settings):
    """The associated poses (evo's sync, then downsampling and motion filter): the matched estimate
    indices and the matched reference and estimate."""
    t_offset, downsample, motion_filter = o.t_offset, o.downsample, o.motion_filter
    i_ref, i_est = associate(ref, est, t_max_diff=o.t_max_diff, t_offset=t_offset)
    r, e = ref.take(i_ref), est.take(i_est)
    if o.sync_method == "interpolation":  # the denser one resampled at the other's matched stamps (evo)
        r, e = (
            (r, prepare.interpolate(est, r.t - t_offset))
            if len(est) > len(ref)
            else (prepare.interpolate(ref, e.t + t_offset), e)
        )
    if downsample is not None or motion_filter is not None:
        keep = prepare.thin(r, downsample, motion_filter)
        r, e = r.take(keep), e.take(keep)
    return i_est, r, e


def _add_rpe(out: Score, relations, o: Settings) -> None:
    """The RPE of each relation over the pairs ``o.delta`` apart (on the reference or the aligned estimate)."""
    r, moved = out.reference, out.aligned
    base = r if o.pairs_from_reference else moved
    i, j = pose_error.pairs(
        p=base.p, q=base.q, t=base.t, delta=o.delta, unit=o.delta_unit, all_pairs=o.all_pairs, rel_tol=o.rel_tol
    )
    out.rpe_pairs = (i, j)
    for rel in relations:
        out.rpe[rel], axes = pose_error.rpe(p_ref=r.p, q_ref=r.q, p_est=moved.p, q_est=moved.q, i=i, j=j, relation=rel)
        if axes is not None:
            out.rpe_axes = axes


def _by_length(ref: Trajectory, r: Trajectory, e: Trajectory, lengths, method: str, scale: float) -> dict:
    """Relative errors over lengths (:mod:`replay.trajectory.lengths`) of the matched estimate as recorded;
    ``ref`` is the windowed reference, whose path length is the total."""
    items = by_length.parse(lengths) if isinstance(lengths, str) else list(lengths)
    return by_length.relative_errors(
        ref_path_length=float(by_length.distances(ref.p)[-1]),
        p_ref=r.p,
        q_ref=r.q,
        p_est=e.p,
        q_est=e.q,
        items=items,
        method=method,
        scale=scale,
    )


def _rmse(x) -> float:
    x = np.asarray(x, float)
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def _track_cells(track: Trajectory, ref: Trajectory, lost_threshold, lost_steps) -> tuple[dict, np.ndarray]:
    """pos_rmse, axes, final_err, drift_pct, lost and the position NEES of ``track`` against ``ref``."""
    err = track.p - ref.p
    norm = np.linalg.norm(err, axis=1)
    dist = metrics.path_length(ref.p)
    cells = {
        "pos_rmse": _rmse(norm),
        "x_rmse": _rmse(err[:, 0]),
        "y_rmse": _rmse(err[:, 1]),
        "z_rmse": _rmse(err[:, 2]),
        "final_err": float(norm[-1]),
        "drift_pct": 100.0 * float(norm[-1]) / dist if dist > 0 else float("nan"),
        "nees": float("nan"),
    }
    lost = metrics.lost_track(norm, lost_threshold, lost_steps)
    cells["lost"] = "" if lost is None else int(lost)
    nees = None
    if track.cov is not None:
        nees = metrics.nees(err, track.cov[:, :3, :3])
        if np.isfinite(nees).any():
            cells["nees"] = float(np.nanmean(nees))
    return cells, nees


def row_metrics(s: Score, *, lost_threshold: float | None = None, lost_steps: int = 10) -> dict:
    """Leaderboard cells of one scored estimate (module docstring): of the aligned track (its
    covariance rotated with it), and, when an alignment moved it, ``*_unaligned`` of the track as recorded."""
    row, nees = _track_cells(s.aligned, s.reference, lost_threshold, lost_steps)
    row.update(ate=_rmse(np.linalg.norm(s.ape_axes, axis=1)), nis=float("nan"), pos_rmse_median=row["pos_rmse"])
    row["lost_share"] = float("nan") if row["lost"] == "" else float(row["lost"])
    if nees is not None:
        row.update({k: v for k, v in metrics.consistency(nees[None, :], 3, "anees").items()})
    if s.options["align"] != "none" or s.options["align_origin"]:
        raw, _ = _track_cells(s.estimate, s.reference, lost_threshold, lost_steps)
        row.update({f"{k}_unaligned": raw[k] for k in ("pos_rmse", "nees", "lost")})
    for rel, e in s.ape.items():
        row.update({f"ape_{rel}_{k}": v for k, v in pose_error.statistics(e).items()})
    for axis, k in zip("xyz", range(3)):
        row[f"ape_{axis}_rmse"] = _rmse(s.ape_axes[:, k])
    for rel, e in s.rpe.items():
        row.update({f"rpe_{rel}_{k}": v for k, v in pose_error.statistics(e).items()})
    if s.rpe_axes is not None:
        for axis, k in zip("xyz", range(3)):
            row[f"rpe_{axis}_rmse"] = _rmse(s.rpe_axes[:, k])
        i, j = s.rpe_pairs
        D = pose_error.accumulated_distances(s.reference.p)
        seg = D[j] - D[i]
        ok = seg > 0
        row["rpe_drift_pct"] = (
            float(np.mean(100.0 * np.linalg.norm(s.rpe_axes[ok], axis=1) / seg[ok])) if ok.any() else float("nan")
        )
    row["matched"] = len(s.reference)
    row["unmatched"] = s.unmatched
    row["scale"] = float(s.transform[2])
    row["scored"], row["masked"] = len(s.reference), 0
    return row
