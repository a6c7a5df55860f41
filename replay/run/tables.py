"""An evaluation as pandas DataFrames (``Evaluation.leaderboard()``, ``.estimates(filter)``, ...).

* :func:`leaderboard` — one row per filter, the columns and values of ``leaderboard.csv``
  (:mod:`replay.scoring.summary`; the CSV and the DataFrame keep every digit; empty cells, such as the
  baseline's paired cells, are NaN).
* :func:`estimates` — a filter's posterior means and variances, one row per run and step
  (index ``run, k``; columns ``t``, ``x0..``, ``P00..``: the columns of
  ``estimates/<filter>.csv.gz``).
* :func:`errors` — a filter's errors against the reference, one row per run and step:
  ``err_<axis>`` (estimate minus reference, m), ``err`` (their norm), ``err_<angle>``
  (wrapped, rad) where the task scores angles; NaN where not scored.
* :func:`run_metrics` — the per-run metrics of every filter (one row per filter and run).
* :func:`paired` — every two filters compared run by run (``paired.csv`` of a campaign).
* :func:`rmse_over_time` — RMSE of the position error across runs at each step, per filter.
"""

from __future__ import annotations

import numpy as np

from replay.scoring import summary
from replay.scoring.scorer import rmse_over_time as _rmse_over_time
from replay.util import covcols
from replay.util.errors import ReplayError


def _pd():
    # lazy: pandas takes ~0.7 s to import (measured by h-imports), only when a table is asked for
    import pandas as pd  # noqa: PLC0415

    return pd


def result(ev, name: str):
    """The :class:`replay.run.evaluation.FilterResult` of filter ``name`` (its name or its label)."""
    for r in ev.results:
        if name in (r.name, r.summary.get("label")):
            return r
    raise ReplayError(f"no filter {name!r} in this evaluation (filters: {', '.join(r.name for r in ev.results)})")


def leaderboard(ev):
    """The leaderboard rows as a DataFrame with the columns of ``leaderboard.csv``."""
    pd = _pd()
    rows = [{k: (np.nan if isinstance(v, str) and v == "" else v) for k, v in row.items()} for row in ev.rows]
    df = pd.DataFrame(rows, columns=summary.columns(ev.rows))
    for col in df.columns:  # a column of numbers and empty cells: numbers
        if df[col].dtype == object and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in df[col]):
            df[col] = df[col].astype(float)
    return df


def _index(runs: list[int], n: list[int]):
    pd = _pd()
    run = np.concatenate([np.full(k, r) for r, k in zip(runs, n)]) if runs else np.zeros(0, int)
    step = np.concatenate([np.arange(k) for k in n]) if runs else np.zeros(0, int)
    return pd.MultiIndex.from_arrays([run, step], names=["run", "k"])


def _runs(res, run):
    if run is None:
        return list(range(len(res.estimates)))
    if not 0 <= run < len(res.estimates):
        raise ReplayError(f"run {run}: this evaluation has runs 0..{len(res.estimates) - 1}")
    return [run]


def estimates(ev, name: str, *, run: int | None = None):
    """Filter ``name``'s estimates: index (run, k); columns t, x0.., P00.., P{i}_{j} (the covariances
    among the position components) (``run``: one run, index k)."""
    pd = _pd()
    res = result(ev, name)
    runs = _runs(res, run)
    est = [res.estimates[r] for r in runs]
    nx = est[0].x.shape[1]
    x = np.concatenate([e.x for e in est])
    var = np.concatenate([np.diagonal(e.P, axis1=1, axis2=2) for e in est])
    t = np.concatenate([ev.t[: len(e.x)] for e in est])
    data = {"t": t, **{f"x{i}": x[:, i] for i in range(nx)}, **{f"P{i}{i}": var[:, i] for i in range(nx)}}
    pidx = ev.position_components(name)  # the covariances of estimates/<filter>.csv.gz: the position's
    data.update(covcols.covariance_columns(np.concatenate([e.P for e in est]), pidx))
    df = pd.DataFrame(data, index=_index(runs, [len(e.x) for e in est]))
    return df.droplevel("run") if run is not None else df


def errors(ev, name: str, *, run: int | None = None):
    """Filter ``name``'s errors against the reference: index (run, k); columns t, err_<axis>.., err, err_<angle>.."""
    pd = _pd()
    res = result(ev, name)
    runs = _runs(res, run)
    errs = [res.errors[r] for r in runs]
    pos = np.concatenate([np.asarray(e["position"], float) for e in errs])
    n = [len(e["position"]) for e in errs]
    data = {"t": np.concatenate([ev.t[:k] for k in n])}
    for i, axis in enumerate(ev.axis_names[: pos.shape[1]]):
        data[f"err_{axis}"] = pos[:, i]
    data["err"] = np.sqrt(np.sum(pos**2, axis=1))
    for key in errs[0]:
        if key != "position" and np.ndim(errs[0][key]) == 1:
            data[f"err_{key}"] = np.concatenate([np.asarray(e[key], float) for e in errs])
    df = pd.DataFrame(data, index=_index(runs, n))
    return df.droplevel("run") if run is not None else df


def run_metrics(ev):
    """Per-run metrics of every filter: one row per filter and run (``filter``, ``run``, metrics)."""
    pd = _pd()
    rows = []
    for res in ev.results:
        for rec in res.records:
            rows.append({"filter": res.name, "run": rec.run, "status": rec.status, **(rec.metrics or {})})
    return pd.DataFrame(rows)


def paired(ev, *, metrics=("pos_rmse", "ate")):
    """Every two filters compared on the same runs: ``a, b, metric, n, diff, diff_ci95, a_better``
    (mean over runs of a's value minus b's and the 95 % half-width; common random numbers)."""
    pd = _pd()
    configs = {r.config_hash: r.config for r in ev.results}
    records = {r.config_hash: r.records for r in ev.results}
    rows = summary.paired_rows(ev.rows, configs, records, tuple(metrics))
    return pd.DataFrame(rows, columns=["dataset", "task", "a", "b", "metric", "n", "diff", "diff_ci95", "a_better"])


def rmse_over_time(ev, *, filters=None):
    """RMSE of the position error across runs at each step: index t, one column per filter (m)."""
    pd = _pd()
    chosen = [result(ev, f) for f in filters] if filters else ev.results
    data = {}
    for res in chosen:
        curve = _rmse_over_time([np.asarray(e["position"], float) for e in res.errors])
        data[res.name] = np.concatenate([curve, np.full(len(ev.t) - len(curve), np.nan)])
    return pd.DataFrame(data, index=pd.Index(ev.t, name="t"))
