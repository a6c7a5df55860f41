"""Helpers shared by the reproductions of papers 001 and 003: planned evaluations, tables, plots.

A reproduction is a list of :class:`Job` (one ``replay eval`` configuration
each: dataset parameters, filters and their parameters, task parameters),
computed by :func:`run_jobs` through :func:`replay.run.evaluation.evaluate` with one
progress line per job. Tables combine rows of several jobs (:func:`combine`):
the leaderboard rows of the evaluations, relabelled, with the paired columns
recomputed over the union by :func:`replay.scoring.summary.add_paired` (the code of
``replay eval``'s ``pos_rmse_vs_<baseline>``): jobs with the same seed, dataset
and task parameters ran on the same measurements (common random numbers).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import numpy as np

from replay.scoring import summary
from replay.run.evaluation import Evaluation, evaluate
from replay.run.manifest import command_line
from replay.scoring.metrics import paired

from .verdict import cell, result_rows


@dataclass
class Job:
    """One evaluation: ``filters`` with ``filter_params`` on ``dataset`` with ``dataset_params``."""

    key: str
    dataset: str
    filters: tuple
    dataset_params: dict = field(default_factory=dict)
    filter_params: dict = field(default_factory=dict)
    task_params: dict = field(default_factory=dict)
    runs: int = 0  # 0: the reproduction's default


def run_jobs(jobs: list[Job], runs: int, seed: int, data_dir=None, quiet: bool = False) -> dict[str, Evaluation]:
    """Every job through :func:`evaluate` (one progress line each on stderr unless ``quiet``)."""
    out = {}
    for i, job in enumerate(jobs, 1):
        if job.key in out:
            raise ValueError(f"job {job.key!r} planned twice")
        n = job.runs or runs
        if not quiet:
            print(f"[{i}/{len(jobs)}] {job.key} ({n} runs) ...", file=sys.stderr, flush=True)
        out[job.key] = evaluate(
            job.dataset,
            filters=job.filters,
            runs=n,
            seed=seed,
            data_dir=data_dir,
            dataset_params=job.dataset_params,
            filter_params=job.filter_params,
            task_params=job.task_params or None,
        )
    return out


def row(ev: Evaluation, name: str | None = None) -> tuple:
    """(evaluation, index of the filter ``name``, or the only/first one)."""
    i = 0 if name is None else next(j for j, r in enumerate(ev.results) if r.name == name)
    return ev, i


def combine(items: list[tuple], metrics=("pos_rmse",)) -> list[dict]:
    """Leaderboard rows of ``items`` = [(label, (evaluation, index)), ...] as one table.

    The first item is the baseline: every row on the same measurements gets
    ``<metric>_vs_base`` and ``<metric>_vs_base_ci95`` (paired, per run), for each metric.
    """
    rows, configs, records = [], {}, {}
    for label, (ev, i) in items:
        res = ev.results[i]
        r = {k: v for k, v in ev.rows[i].items() if "_vs_" not in k}
        r["label"] = label
        r["_command"] = command(ev, i)
        rows.append(r)
        configs[r["config_hash"]], records[r["config_hash"]] = res.config, res.records
    base = rows[0]["label"]
    for m in metrics:
        summary.add_paired(rows, configs, records, baseline=base, metric=m)
        for r in rows:
            for suffix in ("", "_ci95"):
                v = r.pop(f"{m}_vs_{base}{suffix}", None)
                if v is not None and r["label"] != base:
                    r[f"{m}_vs_base{suffix}"] = v
    return rows


def diff_cell(r: dict, metric: str = "pos_rmse", digits: int = 3) -> str:
    """``+d ± h`` of a combined row's paired column (``–`` for the baseline, ``n/a`` when unpaired)."""
    d, h = r.get(f"{metric}_vs_base"), r.get(f"{metric}_vs_base_ci95")
    if d is None:
        return "–"
    try:
        d, h = float(d), float(h)
    except (TypeError, ValueError):
        return "n/a"
    if not np.isfinite(d):
        return "n/a"
    mark = " (lower)" if np.isfinite(h) and d + h < 0 else (" (higher)" if np.isfinite(h) and d - h > 0 else "")
    return f"{d:+.{digits}f} ± {h:.{digits}f}{mark}"


def table(
    rows: list[dict], metrics=("pos_rmse",), paired_metrics=("pos_rmse",), digits: int = 3, base_name: str | None = None
) -> str:
    """:func:`result_rows` (mean ± 95 %, median, lost k/N, diverged) plus a paired column per metric
    in ``paired_metrics``: this row minus the first row, run by run, with its 95 % interval."""
    base = base_name or rows[0]["label"]
    lines = result_rows(rows, metrics=metrics, digits=digits).split("\n")
    lines[0] += "".join(f" Δ {m} vs {cell(base)} (paired) |" for m in paired_metrics)
    lines[1] += "---|" * len(paired_metrics)
    for j, r in enumerate(rows):
        lines[2 + j] += "".join(f" {diff_cell(r, m, digits)} |" for m in paired_metrics)
    return "\n".join(lines)


def command(ev: Evaluation, i: int = 0) -> str:
    """The ``replay eval`` command of filter ``i`` of ``ev`` alone (task parameters included)."""
    cfg = dict(ev.config)
    name = ev.results[i].name
    cfg["filters"] = [name]
    cfg["filter_params"] = {name: ev.results[i].params}
    return command_line(cfg)  # names the task parameters that differ from their defaults


def commands(rows: list[dict]) -> str:
    """The commands of a combined table, one bullet per row."""
    return "\n".join(f"- {cell(r['label'])}: `{r['_command']}`" for r in rows)


def per_run(ev: Evaluation, i: int, metric: str) -> np.ndarray:
    """A metric per run of filter ``i`` (NaN for diverged runs), from the evaluation's records."""
    return np.array([np.nan if r.get("diverged") else r.get(metric, np.nan) for r in ev.results[i].runs])


def paired_cell(a, b, digits: int = 3) -> str:
    """Paired mean of a − b over runs with its 95 % half-width (:func:`replay.scoring.metrics.paired`)."""
    p = paired(a, b)
    if not np.isfinite(p["diff"]):
        return "n/a"
    return f"{p['diff']:+.{digits}f} ± {p['diff_ci95']:.{digits}f}"


def mean_ci(values, digits: int = 3) -> str:
    from replay.scoring.scorer import ci95

    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return f"{v.mean():.{digits}f} ± {ci95(v):.{digits}f}" if len(v) else "n/a"


def rmse_curve(err: np.ndarray) -> np.ndarray:
    """RMSE across runs at each step of errors (runs, n): sqrt(mean_runs e²), NaN-aware."""
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.nanmean(err**2, axis=0))


def rmse_figures(t, errors: dict, quantities, title: str) -> dict:
    """One figure per quantity ``(key, name, unit)``: a panel per filter with the RMSE over the runs
    at each step (the papers' curves) and the 5-95 % band of the runs' absolute errors. ``errors``:
    {filter label: {key: (runs, steps) errors}}; ``title`` starts each figure's title."""
    from replay.outputs.plots import mc_figure

    figs = {}
    for key, name, unit in quantities:
        curves = {label: e[key] for label, e in errors.items()}
        runs = min(len(v) for v in curves.values())
        figs[key] = mc_figure(
            t,
            curves,
            name,
            unit,
            f"{title}: {name} over time, {runs} runs (line: RMSE over the runs; band: 5-95 % of the runs' |error|)",
            stat="rmse",
        )
    return figs
