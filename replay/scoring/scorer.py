"""Scoring estimates against the reference.

Per run (:func:`score_run`), over the samples where the reference is valid and
the filter has an estimate:

* ``pos_rmse``  = sqrt(mean_k |p^_k - p_k|^2)  (3-D position RMSE, metres)
* ``<axis>_rmse`` = sqrt(mean_k (p^_k,a - p_k,a)^2) for each axis a
* ``<angle>_rmse`` = sqrt(mean_k wrap(a^_k - a_k)^2) for each scored angle
* ``<name>_rmse`` = sqrt(mean_k (x^_k,i - x_k,i)^2) for each other scored state
  component ``Problem.truth_extra[name] = (truth, i)`` (NaN truth = not scored)
* ``scored`` / ``masked``: samples used, and samples skipped because the
  reference is masked there (e.g. jumps of a navigation solution).

Over part of a run (:func:`score_where`): the same metrics over the samples of a
time mask, e.g. :func:`within` a frame's maneuver segments and its complement.

Over Monte Carlo runs (:func:`aggregate`):

* ``<metric>`` is the **mean over runs of the per-run RMSE**, with
  ``<metric>_ci95`` the half-width of its 95 % interval (Student t);
* :func:`rmse_over_time` gives the **RMSE across runs at each time step**,
  sqrt(mean_runs |e_k|^2) — the curve papers plot.

Diverged runs (non-finite or non-positive covariance) are counted in
``diverged`` and left out of the means.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from replay.util.angles import wrap


def errors(problem, est) -> dict:
    """Error series of one run: ``position`` (n, d) and each angle (n,); NaN where not scored."""
    pos = est.x[:, list(problem.position_index)] - problem.truth_position
    ok = problem.truth_valid & np.isfinite(pos).all(axis=1)
    out = {"position": np.where(ok[:, None], pos, np.nan)}
    for name, truth in problem.truth_angles.items():
        e = wrap(est.x[:, problem.angle_index[name]] - truth)
        out[name] = np.where(ok, e, np.nan)
    for name, (truth, i) in getattr(problem, "truth_extra", {}).items():
        out[name] = np.where(ok, est.x[:, i] - truth, np.nan)
    return out


def score_run(problem, est, err: dict | None = None) -> dict:
    """RMSE metrics of one run (see the module docstring); ``err``: its :func:`errors`, when computed."""
    err = errors(problem, est) if err is None else err
    pos = err["position"]
    ok = np.isfinite(pos).all(axis=1)
    e = pos[ok]
    m = {"pos_rmse": float(np.sqrt(np.mean(np.sum(e**2, axis=1)))) if len(e) else np.nan}
    for j, axis in enumerate(problem.axis_names):
        m[f"{axis}_rmse"] = float(np.sqrt(np.mean(e[:, j] ** 2))) if len(e) else np.nan
    for name in [*problem.truth_angles, *getattr(problem, "truth_extra", {})]:
        a = err[name][np.isfinite(err[name])]
        m[f"{name}_rmse"] = float(np.sqrt(np.mean(a**2))) if len(a) else np.nan
    m["scored"] = int(ok.sum())
    present = getattr(problem, "truth_present", None)  # where the reference has a sample at all
    m["masked"] = int((~problem.truth_valid if present is None else present & ~problem.truth_valid).sum())
    m["masked"] += getattr(problem, "truth_missing", 0)  # a reference ending early: its samples not given
    m["us_per_step"] = est.us_per_step
    m["diverged"] = bool(est.diverged)
    m["still"] = still(est.x[:, list(problem.position_index)])
    return m


# A position estimate that moves less than this share of its magnitude (at least 1 m) over a whole
# run has not moved: what a filter with no position input and no velocity it uses gives (every
# estimate its start), whose error is the start's, not a filter's.
STILL_REL = 1e-9


def still(positions) -> bool:
    """Whether a run's position estimates (n, d) never move: every finite estimate within
    :data:`STILL_REL` x max(1, largest coordinate) of the first (False with fewer than 2)."""
    p = np.asarray(positions, float)
    p = p[np.isfinite(p).all(axis=1)] if p.ndim == 2 else p[:0]
    if len(p) < 2:
        return False
    return bool(np.max(np.abs(p - p[0])) <= STILL_REL * max(1.0, float(np.max(np.abs(p)))))


def within(t, spans) -> np.ndarray:
    """A bool per time of ``t``: inside any span ``[t0, t1, ...]`` of ``spans`` (t0 <= t < t1; further items,
    e.g. a label, ignored), such as a frame's ``maneuvers``."""
    t = np.asarray(t, float)
    inside = np.zeros(t.shape, bool)
    for t0, t1, *_ in spans:
        inside |= (t >= t0) & (t < t1)
    return inside


def score_where(problem, est, keep) -> dict:
    """:func:`score_run` over the samples where ``keep`` (a bool per step) holds: the reference elsewhere is left
    out as if masked (``masked`` counts it). With ``keep`` and ``~keep`` the two parts' RMSE combine, weighted by
    their ``scored`` samples, into the whole run's."""
    return score_run(replace(problem, truth_valid=problem.truth_valid & np.asarray(keep, bool)), est)


def units(problem) -> dict:
    """The unit of each RMSE metric :func:`score_run` gives: position axes in the task's
    ``position_unit`` (m), angles in rad, extra states as the task declares them."""
    out = {"pos_rmse": problem.position_unit}
    out.update({f"{a}_rmse": problem.position_unit for a in problem.axis_names})
    out.update({f"{a}_rmse": "rad" for a in problem.truth_angles})
    out.update(
        {f"{a}_rmse": getattr(problem, "extra_units", {}).get(a, "?") for a in getattr(problem, "truth_extra", {})}
    )
    return out


# Runs whose values differ by less than this share of the largest are one deterministic value: a
# deterministic filter's runs computed in one batch can differ in the last bits (sums taken in
# another order: about 1e-16 relative), a Monte Carlo spread is many orders of magnitude larger.
DETERMINISTIC_REL = 1e-12


def deterministic(values) -> bool:
    """Whether the finite ``values`` (two or more) are one value up to rounding: all bitwise equal,
    or their range at most :data:`DETERMINISTIC_REL` times the largest magnitude."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return len(v) >= 2 and float(np.ptp(v)) <= DETERMINISTIC_REL * float(np.max(np.abs(v)))


def ci95(values) -> float:
    """Half-width of the 95 % Student-t interval of the mean of ``values``; exactly 0 for values
    that are one value up to rounding (:func:`deterministic`), not the 1e-16 of their last bits."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if len(v) < 2:
        return float("nan")
    if deterministic(v):
        return 0.0
    return float(t_ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v)))


def t_ppf(q: float, df):
    """``scipy.stats.t.ppf(q, df)`` for 0 < q < 1 (NaN where df <= 0), bit for bit: the function
    it evaluates, ``scipy.special.stdtrit``, without importing scipy.stats (0.5-1 s)."""
    # lazy: start-up, scipy.special measured ~420 ms
    from scipy.special import stdtrit  # noqa: PLC0415

    df = np.asarray(df, float)
    with np.errstate(invalid="ignore"):
        out = np.where(df > 0, stdtrit(df, q), np.nan)
    return out[()] if out.ndim == 0 else out


def aggregate(run_metrics: list[dict], names=()) -> dict:
    """Monte Carlo summary of per-run metrics: ``runs``, ``diverged``, and for every ``*_rmse``
    metric and every metric in ``names`` the mean over non-diverged runs with the half-width of
    its 95 % interval (``<m>_ci95``); ``us_per_step`` (median), ``scored``/``masked`` (mean).
    The one aggregation of every leaderboard (:func:`replay.scoring.summary.config_row`)."""
    ok = [m for m in run_metrics if not m["diverged"]]
    out = {
        "runs": len(run_metrics),
        "diverged": len(run_metrics) - len(ok),
        "lost": sum(1 for m in ok if m.get("lost")),
    }
    keys = list(names)
    for m in run_metrics:
        keys += [k for k in m if k.endswith("_rmse") and k not in keys]
    for k in keys:
        vals = np.asarray([m.get(k, np.nan) for m in ok], float)
        out[k] = float(np.nanmean(vals)) if np.isfinite(vals).any() else float("nan")
        out[f"{k}_ci95"] = ci95(vals)
        if k == "pos_rmse":  # beside the mean: a few lost runs move the mean, not the median
            out["pos_rmse_median"] = float(np.nanmedian(vals)) if np.isfinite(vals).any() else float("nan")
    us = [m["us_per_step"] for m in run_metrics if np.isfinite(m["us_per_step"])]
    out["us_per_step"] = float(np.median(us)) if us else float("nan")
    out["scored"] = int(np.mean([m["scored"] for m in run_metrics])) if run_metrics else 0
    out["masked"] = int(np.mean([m["masked"] for m in run_metrics])) if run_metrics else 0
    return out


def rmse_over_time(error_runs: list[np.ndarray]) -> np.ndarray:
    """RMSE across runs at each step: sqrt(mean over runs of |e_k|^2), NaN-aware.

    ``error_runs`` holds one (n, d) or (n,) error array per run.
    """
    e = np.stack([x if x.ndim == 2 else x[:, None] for x in error_runs])
    sq = np.sum(e**2, axis=2)
    sq = np.where(np.isfinite(sq), sq, np.nan)
    counts = np.isfinite(sq).sum(axis=0)
    total = np.nansum(sq, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, np.sqrt(total / np.maximum(counts, 1)), np.nan)
