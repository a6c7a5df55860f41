"""Recorded estimates (``Frame.estimates``: an onboard EKF's odometry, a SLAM system's poses) as
configurations of the pipeline: ``filter = "recorded:<name>"`` with the association parameters
:data:`RECORDED_PARAMS`. Nothing is filtered: :func:`recorded_estimates` associates the recorded poses
with the task's reference (:func:`replay.trajectory.associate.associate_times`, evo's rule) and the
pipeline scores them as any filter's estimates (:func:`replay.run.pipeline.run_block`).
"""

from __future__ import annotations

import copy

import numpy as np

from replay.scoring.align import ALIGNMENTS, align, apply
from replay.trajectory.associate import associate_times
from replay.util.errors import ReplayError
from replay.util.params import Param, validate
from replay.filters.base import Estimates
from replay.scoring.metrics import run_metrics

RECORDED = "recorded:"  # the filter name of a recorded estimate's configuration: recorded:<name>
RECORDED_PARAMS = (
    Param(
        "t_max_diff",
        float,
        0.01,
        "a recorded pose and a reference sample are associated when their stamps "
        "differ by at most this (nearest stamp, as evo's --t_max_diff)",
        unit="s",
        low=0.0,
    ),
    Param("t_offset", float, 0.0, "added to the recorded stamps before association (evo's --t_offset)", unit="s"),
    Param(
        "align",
        str,
        "none",
        "the recorded trajectory is first moved onto the reference by this fit over "
        "the associated poses (as evo's -a / --correct_scale; for an estimate in its own frame, a SLAM map): "
        "every column, the covariance (NEES) and the lost judgement are then of the aligned track, and "
        "pos_rmse/nees/lost_unaligned give the numbers before it. none: scored as recorded (an estimate in the "
        "reference's frame, whose offset is an error)",
        choices=ALIGNMENTS,
    ),
)


def is_recorded(name: str) -> bool:
    """Whether a configuration's ``filter`` names a recorded estimate (``recorded:<name>``)."""
    return isinstance(name, str) and name.startswith(RECORDED)


def recorded_params(name: str, given: dict | None = None, defaults: dict | None = None) -> dict:
    """The association parameters of ``recorded:<name>``: ``given`` over the mapping's ``defaults``
    over the declared ones, checked (one line naming the parameter)."""
    return validate(RECORDED_PARAMS, {**(defaults or {}), **(given or {})}, f"recorded estimate {name!r}")


def recorded_estimates(problem, name: str, params: dict):
    """(problem to score, Estimates, note): ``recorded:<name>`` on the problem's time axis.

    Each associated pose is placed at its reference sample (its own stamp differs by at
    most ``t_max_diff``); the other samples hold NaN and are not scored. Two poses on one
    reference sample (the estimate denser there): the nearer is kept. The scored
    position is the first d components (the task's axes); the covariance is the d x d
    block where recorded and positive definite (NEES), NaN elsewhere. Fewer than 3
    associated poses: one line naming the file and topic.
    """
    rec = getattr(problem, "recorded", {}).get(name)
    src = getattr(problem, "source", "dataset")
    if rec is None:
        known = ", ".join(getattr(problem, "recorded", {})) or "none"
        raise ReplayError(f"{src}: no recorded estimate {name!r} (the mapping's [estimates] declare: {known})")
    d = len(problem.axis_names)
    ref = np.flatnonzero(problem.truth_valid)
    i, j = associate_times(problem.t[ref], rec.t, params["t_max_diff"], params["t_offset"])
    k = ref[i]
    dt = np.abs(problem.t[k] - rec.t[j] - params["t_offset"])
    order = np.lexsort((dt, k))
    first = np.r_[True, np.diff(k[order]) != 0] if len(k) else np.zeros(0, bool)
    k, j, dup = k[order][first], j[order][first], int((~first).sum())
    if len(k) < 3:
        raise ReplayError(
            f"{src}: recorded estimate {name} ({rec.description}): {len(k)} pose(s) associated with "
            f"the reference within t_max_diff {params['t_max_diff']:g} s (t_offset "
            f"{params['t_offset']:g} s); at least 3 are needed: check the stamps, or raise "
            f"t_max_diff (-p recorded:{name}.t_max_diff=..., or in the mapping's [estimates])"
        )
    n = len(problem.t)
    x, P = np.full((n, d), np.nan), np.full((n, d, d), np.nan)
    R, t, c = align(rec.position[j, :d], problem.truth_position[k], params["align"])
    x[k] = apply(R, t, c, rec.position[j, :d])
    if rec.covariance is not None:
        block = c * c * R @ rec.covariance[j][:, :d, :d] @ R.T
        ok = np.isfinite(block).all(axis=(1, 2))
        ok[ok] = np.all(np.linalg.eigvalsh(block[ok]) > 0, axis=1)
        P[k[ok]] = block[ok]
    info = {"recorded": name, "associated": int(len(k))}
    if params["align"] != "none":  # the track as recorded, for the *_unaligned numbers (unaligned_metrics)
        x0, P0 = np.full((n, d), np.nan), np.full((n, d, d), np.nan)
        x0[k] = rec.position[j, :d]
        if rec.covariance is not None:
            raw = rec.covariance[j][:, :d, :d]
            fine = np.isfinite(raw).all(axis=(1, 2))
            fine[fine] = np.all(np.linalg.eigvalsh(raw[fine]) > 0, axis=1)
            P0[k[fine]] = raw[fine]
        info["unaligned"] = Estimates(x0, P0, np.full(n, np.nan), None, {"recorded": name})
    est = Estimates(x, P, np.full(n, np.nan), None, info)
    scored = copy.copy(problem)  # the position only: a recorded state has no task-specific components
    scored.position_index, scored.truth_angles, scored.angle_index, scored.truth_extra = tuple(range(d)), {}, {}, {}
    note = (
        f"recorded:{name}: {len(k)} of its {len(rec)} poses associated with {len(ref)} reference samples "
        f"(nearest stamp within {params['t_max_diff']:g} s, t_offset {params['t_offset']:g} s"
        + (f"; moved onto the reference by a {params['align']} fit" if params["align"] != "none" else "")
        + (f"; {dup} more pose(s) on an already associated sample left out" if dup else "")
        + "); position scored, one run (a recorded estimate is deterministic)"
    )
    return scored, est, note


UNALIGNED = ("pos_rmse", "nees", "lost")


def unaligned_metrics(problem, est, divergence_threshold=None) -> dict:
    """``pos_rmse_unaligned``, ``nees_unaligned``, ``lost_unaligned``: the numbers of a recorded track
    before its ``align`` fit (empty when it was not moved), beside the aligned ones of every column."""
    raw = est.info.get("unaligned")
    if raw is None:
        return {}
    m, _ = run_metrics(problem, raw, "none", divergence_threshold)
    out = {f"{k}_unaligned": m[k] for k in UNALIGNED}
    out["lost_unaligned"] = None if m["lost"] is None else int(m["lost"])  # as the lost count of one run
    return out
