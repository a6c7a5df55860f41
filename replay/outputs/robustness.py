"""Robustness sweeps: how each filter's error grows with a fault's intensity (``[[fault]]`` with
``sweep``, :mod:`replay.campaign.fault_axis`), and how fast it recovers after an outage.

:func:`sweeps` reads leaderboard rows (a campaign's, with the ``view`` column ``fault=SPEC;...``)
and finds the swept fault: the rows of one dataset and task whose fault lists differ in one
parameter of one fault. Per sweep, :func:`table` gives each filter's metric (mean over runs and
its 95 % half-width) and lost-track share at each intensity, and the **robustness score**: the
area under the degradation curve divided by the intensity range (trapezoids; the metric's mean
over the swept range, in the metric's unit: lower is more robust). :func:`figure` draws the
curves (intensity on x, error on y, one line per filter with its band).

:func:`recovery_time` is the time to recover after an outage: seconds from the outage's end until
the position error returns within ``factor`` (2) times its pre-outage level (the median error over
the outage's length before it, or what there is); NaN when it never does.
"""

from __future__ import annotations

import math
import re
from collections import defaultdict
from pathlib import Path

import numpy as np

from replay.data import faults
from replay.outputs import plots


def _float(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _faults_of(row) -> list[str] | None:
    view = str(row.get("view") or "")
    for part in view.split(" "):
        if part.startswith("fault="):
            return part[len("fault=") :].split(";")
    return None


def sweeps(rows) -> list[dict]:
    """The robustness sweeps among ``rows``: ``{"dataset", "task", "fault", "parameter",
    "rows": [(intensity, row), ...]}`` (the fault shown with the swept parameter as ``NAME=*``)."""
    groups = defaultdict(list)
    for row in rows:
        specs = _faults_of(row)
        if not specs:
            continue
        parsed = [faults.parse(s) for s in specs]
        for k, (channel, kind, values) in enumerate(parsed):
            for name, value in values.items():
                if not isinstance(value, float):
                    continue
                rest = [faults.canonical(*p) for j, p in enumerate(parsed) if j != k]
                key = (row.get("dataset"), row.get("task"), channel, kind, name, _others(values, name), tuple(rest))
                groups[key].append((value, row))
    out = []
    for key, items in groups.items():
        if len({v for v, _ in items}) < 2:
            continue
        dataset, task, channel, kind, name, others, rest = key
        shown = f"{channel}:{kind}:" + ",".join(f"{k}={'*' if k == name else v}" for k, v in others)
        out.append(
            {
                "dataset": dataset,
                "task": task,
                "fault": shown + "".join(f" + {r}" for r in rest),
                "parameter": name,
                "rows": sorted(items, key=lambda vr: vr[0]),
            }
        )
    return out


def _others(values: dict, name: str) -> tuple:
    """The fault's parameters in declaration order, the swept one as ``*`` (the sweep's key and name)."""
    return tuple((k, "*" if k == name else faults._num(v)) for k, v in values.items() if v is not None)


def table(sweep: dict, metric: str = "pos_rmse") -> tuple[list[dict], dict]:
    """(one row per filter and intensity, {filter: robustness score}) of a sweep."""
    lines, curves = [], defaultdict(list)
    for x, row in sweep["rows"]:
        name = curve(row)
        m, ci, lost = _float(row.get(metric)), _float(row.get(f"{metric}_ci95")), _float(row.get("lost_share"))
        lines.append({"filter": name, sweep["parameter"]: x, metric: m, f"{metric}_ci95": ci, "lost_share": lost})
        curves[name].append((x, m))
    return lines, {name: score(pts) for name, pts in curves.items()}


def curve(row) -> str:
    """The curve a row belongs to: its label without the ``#k`` that tells a report's equal labels apart."""
    return re.sub(r" #\d+$", "", str(row.get("label") or row.get("filter")))


def recoveries(sweep: dict, series: dict, factor: float = 2.0) -> dict:
    """{(filter, intensity): (mean seconds to recover over the runs that do, runs that never do, runs)} of
    an outage sweep (``series``: {row label: {run: {"t", "err"}}}, the report's); {} for another fault."""
    channel_kind = sweep["fault"].split(":")[:2]
    if channel_kind[1] != "outage" or sweep["parameter"] != "d":
        return {}
    t0 = float(re.search(r"t0=([0-9.eE+-]+)", sweep["fault"]).group(1))
    out = {}
    for d, row in sweep["rows"]:
        runs = series.get(str(row.get("label")), {})
        times = []
        for s in runs.values():
            err = np.asarray(s["err"], float)
            norm = np.where(np.isfinite(err).any(axis=1), np.sqrt(np.nansum(err**2, axis=1)), np.nan)
            times.append(recovery_time(s["t"], norm, t0, t0 + d, factor) if d > 0 else 0.0)
        done = [x for x in times if np.isfinite(x)]
        out[(curve(row), d)] = (float(np.mean(done)) if done else math.nan, len(times) - len(done), len(times))
    return out


def score(points) -> float:
    """Area under the degradation curve over the intensity range (trapezoids), divided by the range."""
    pts = sorted(points)
    x, y = np.array([p[0] for p in pts], float), np.array([p[1] for p in pts], float)
    if len(x) < 2 or x[-1] == x[0] or not np.isfinite(y).all():
        return math.nan
    return float(np.sum((y[1:] + y[:-1]) / 2 * np.diff(x)) / (x[-1] - x[0]))


def markdown(sweep: dict, metric: str = "pos_rmse", series: dict | None = None) -> str:
    """The sweep's table (Markdown): filters as rows, intensities as columns, then the score; for an
    outage sweep with ``series`` (:func:`recoveries`), the seconds to recover after each outage."""
    lines, scores = table(sweep, metric)
    rec = recoveries(sweep, series or {})
    xs = sorted({r[sweep["parameter"]] for r in lines})
    head = "| filter | " + " | ".join(f"{sweep['parameter']}={x:g}" for x in xs) + " | score (AUC/range) |"
    data = Path(sweep["dataset"]).name if Path(sweep["dataset"]).is_absolute() else sweep["dataset"]  # no home
    out = [f"{data} ({sweep['task']}), fault {sweep['fault']}: {metric} (± 95 %; lost share)", "", head]
    out.append("|---" * (len(xs) + 2) + "|")
    for name in scores:
        cells = []
        for x in xs:
            r = next((r for r in lines if r["filter"] == name and r[sweep["parameter"]] == x), None)
            cells.append("" if r is None else f"{r[metric]:.3g} ± {r[f'{metric}_ci95']:.2g}; {r['lost_share']:.0%}")
            if (name, x) in rec and x > 0:
                mean, never, n = rec[(name, x)]
                if never == n:
                    cells[-1] += "; never recovers"
                else:
                    cells[-1] += f"; recovers in {mean:.3g} s" + (f" ({never} of {n} runs never)" if never else "")
        out.append(f"| {name} | " + " | ".join(cells) + f" | {scores[name]:.3g} |")
    return "\n".join(out)


def figure(sweep: dict, metric: str = "pos_rmse", palette=None):
    """The degradation curves of a sweep: intensity on x, the metric on y, a band of ± its 95 % half-width."""
    lines, scores = table(sweep, metric)
    fig, axes = plots.figure()
    ax = axes[0, 0]
    for name in scores:
        pts = sorted((r[sweep["parameter"]], r[metric], r[f"{metric}_ci95"]) for r in lines if r["filter"] == name)
        x, y, ci = (np.array(v, float) for v in zip(*pts))
        color = palette.colour(name) if palette is not None else None
        ax.plot(x, y, marker="o", color=color, label=f"{name} (score {scores[name]:.3g})")
        ax.fill_between(x, y - np.nan_to_num(ci), y + np.nan_to_num(ci), color=color, alpha=0.2)
    kind = sweep["fault"].split(":")[1]
    unit = next((p.unit for p in faults.KINDS[kind] if p.name == sweep["parameter"]), "")
    ax.set_xlabel(plots.label(f"{kind} {sweep['parameter']}", unit or None))
    ax.set_ylabel(
        plots.label("position RMSE" if metric == "pos_rmse" else metric, "m" if metric == "pos_rmse" else None)
    )
    ax.set_title(f"{Path(str(sweep['dataset'])).name}: {sweep['fault']}", fontsize=9)
    ax.legend(fontsize=8)
    return fig


def outage_figure(sweep: dict, series: dict, palette=None):
    """The position error over time across the longest outage of an outage sweep: per filter the
    median over the runs of the error norm at each scored step, the outage shaded; None for another fault."""
    if sweep["fault"].split(":")[1] != "outage" or sweep["parameter"] != "d":
        return None
    t0 = float(re.search(r"t0=([0-9.eE+-]+)", sweep["fault"]).group(1))
    d = max(x for x, _ in sweep["rows"])
    fig, axes = plots.figure()
    ax = axes[0, 0]
    for x, row in sweep["rows"]:
        runs = series.get(str(row.get("label")), {})
        if x != d or not runs:
            continue
        first = next(iter(runs.values()))
        err = np.stack([np.asarray(s["err"], float) for s in runs.values()])
        norm = np.where(np.isfinite(err).any(axis=2), np.sqrt(np.nansum(err**2, axis=2)), np.nan)
        ok = np.isfinite(norm).any(axis=0)
        med = np.nanmedian(norm[:, ok], axis=0)
        name = curve(row)
        ax.plot(np.asarray(first["t"], float)[ok], med, color=palette.colour(name) if palette else None, label=name)
    ax.axvspan(t0, t0 + d, color="0.85", label=f"outage ({d:g} s)")
    ax.set_xlabel(plots.label("time", "s"))
    ax.set_ylabel(plots.label("position error (median over runs)", "m"))
    ax.set_title(f"{Path(str(sweep['dataset'])).name}: {sweep['fault'].replace('d=*', f'd={d:g}')}", fontsize=9)
    ax.legend(fontsize=8)
    return fig


def recovery_time(t, err, t0: float, t1: float, factor: float = 2.0) -> float:
    """Seconds after the outage ``[t0, t1)`` ends until ``err`` (a position error norm per step) is
    within ``factor`` times its pre-outage level (median over ``[t0 - (t1 - t0), t0)``); NaN if never
    (or no error before the outage to compare with)."""
    t, err = np.asarray(t, float), np.asarray(err, float)
    ok = np.isfinite(err)
    before = ok & (t < t0) & (t >= t0 - (t1 - t0))
    if not before.any():
        return math.nan
    level = factor * float(np.median(err[before]))
    after = np.flatnonzero(ok & (t >= t1) & (err <= level))
    return float(t[after[0]] - t1) if len(after) else math.nan
