"""What every reproduction document shares: planned evaluations, leaderboard rows as Markdown, the footer.

A reproduction lists its evaluations as :class:`replay.campaign.longest.Job` (one ``replay eval``
configuration each), computed by :func:`replay.campaign.longest.evaluate_jobs` in ``REPLAY_WORKERS``
processes, the costliest first, and returned in the plan's order. Every table row comes
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

import numpy as np

from replay.run.evaluation import Evaluation
from replay.run.manifest import command_line
from replay.scoring import summary
from replay.scoring.summary import lost_cell


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
