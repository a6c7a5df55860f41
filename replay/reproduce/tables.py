"""What every reproduction document shares: planned evaluations, leaderboard rows as Markdown, the footer.

A reproduction lists :class:`Job` (one ``replay eval`` configuration each: dataset and its
parameters, filters and theirs, task parameters, runs, seed offset); :func:`evaluate_jobs` computes
them through :func:`replay.run.evaluation.evaluate` in ``REPLAY_WORKERS`` processes, the costliest
first (:mod:`replay.campaign.longest`), and returns them in the plan's order. Every table row comes
from those evaluations through :func:`result_rows`, so a document shows the columns of a
leaderboard: mean ± 95 % half-width, median, ``lost k/N`` and ``diverged``. :func:`combine` puts
rows of several jobs in one table with the paired columns recomputed over the union by
:func:`replay.scoring.summary.add_paired` (the code of ``replay eval``'s ``pos_rmse_vs_<baseline>``):
jobs with the same seed, dataset and task parameters ran on the same measurements (common random
numbers). :func:`footer` states the command and the total runtime; documents are written by
:func:`replay.util.portable.write_document` (no machine-specific path).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from replay.campaign.longest import pool, run_longest_first, workers
from replay.run.evaluation import Evaluation, evaluate
from replay.run.manifest import command_line
from replay.scoring import summary
from replay.scoring.summary import lost_cell


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
    seed: int = 0  # added to the reproduction's seed


def _evaluate(args):
    """One job's evaluation (what a worker process runs), through ``reduce`` when given."""
    job, runs, seed, data_dir, reduce = args
    params = dict(dataset_params=job.dataset_params or None, filter_params=job.filter_params)
    params |= dict(task_params=job.task_params or None, runs=job.runs or runs, seed=seed + job.seed)
    ev = evaluate(job.dataset, filters=job.filters, data_dir=data_dir, **params)
    return ev if reduce is None else reduce(job, ev)


def evaluate_jobs(jobs: list[Job], runs: int, seed: int, data_dir=None, quiet=False, prefix="", reduce=None) -> dict:
    """``{key: Evaluation}`` of ``jobs`` in the plan's order, computed in worker processes the costliest first
    (runs × particles, 30 for a filter without; a progress line each on stderr unless ``quiet``). ``reduce(job,
    evaluation)``, a module-level function, runs in the worker and its result comes back instead of the
    evaluation (a run's records can weigh a megabyte)."""
    keys = [j.key for j in jobs]
    if len(set(keys)) != len(keys):
        raise ValueError(f"jobs planned twice: {sorted({k for k in keys if keys.count(k) > 1})}")
    runs_of = [j.runs or runs for j in jobs]
    particles = [sum(j.filter_params.get(f, {}).get("n_particles", 30) for f in j.filters) for j in jobs]
    cost, labels = [n * p for n, p in zip(runs_of, particles)], [f"{j.key} ({n} runs)" for j, n in zip(jobs, runs_of)]
    with pool(workers()) as ex:
        args = [(j, runs, seed, data_dir, reduce) for j in jobs]
        done = dict(run_longest_first(_evaluate, args, cost, labels, ex, quiet, prefix))
    return {j.key: done[i] for i, j in enumerate(jobs)}


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


def cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def mean_ci(row: dict, key: str = "pos_rmse", digits: int = 3) -> str:
    """``mean ± half-width`` of a leaderboard row's metric (``n/a`` when not finite)."""
    v, c = row.get(key, np.nan), row.get(f"{key}_ci95", np.nan)
    try:
        v, c = float(v), float(c)
    except (TypeError, ValueError):
        return "n/a"
    if not np.isfinite(v):
        return "n/a"
    return f"{v:.{digits}f}" + (f" ± {c:.{digits}f}" if np.isfinite(c) else "")


def result_rows(rows: list[dict], metrics=("pos_rmse",), names=None, digits: int = 3) -> str:
    """A Markdown table of leaderboard rows (:mod:`replay.scoring.summary`): label (or ``names``), each
    metric as mean ± 95 %, the median position RMSE, ``lost k/N`` and ``diverged k/N``."""
    head = ["filter"] + [m for m in metrics] + ["median pos_rmse", "lost", "diverged"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i, r in enumerate(rows):
        name = names[i] if names else (r.get("label") or r.get("filter"))
        med = r.get("pos_rmse_median", np.nan)
        cells = [cell(name)] + [mean_ci(r, m, digits) for m in metrics]
        cells += [
            f"{float(med):.{digits}f}" if np.isfinite(float(med)) else "n/a",
            lost_cell(r),
            f"{r.get('diverged', 0)}/{r.get('runs', 0)}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def footer(command: str, seconds: float) -> str:
    """The closing lines: the command that wrote the document and its total runtime."""
    mins = seconds / 60
    took = f"{seconds:.0f} s" if seconds < 120 else f"{mins:.1f} min"
    return (
        f"\n---\nGenerated by `{command}` in {took} (2-core machine, total wall time). "
        "Every number comes from `replay.run.evaluation.evaluate`, the pipeline of `replay eval`.\n"
    )


class Stopwatch:
    """Total wall time of a reproduction, for :func:`footer`."""

    def __init__(self):
        self.t0 = time.perf_counter()

    @property
    def seconds(self) -> float:
        return time.perf_counter() - self.t0
