"""Plots from Python: each returns a :class:`matplotlib.figure.Figure` (units on every axis).

* :func:`plot_track` — a frame's reference and GPS track, or an evaluation's reference and
  estimated tracks (one run), on UTM axes when the source is geodetic (``meta["crs"]``,
  ``meta["origin"]``), else on the local east/north axes (m).
* :func:`plot_errors` — position error over time: RMSE across runs per filter (m).

A recorded estimate (``recorded:<name>``: NaN off the reference samples it was associated with) is
drawn as a line through its associated samples (:func:`replay.util.series.joined`), not as dots.
* :func:`plot_rmse` — position RMSE per filter, mean over runs with its 95 % interval (m).
* :func:`plot_paired` — each filter minus the baseline, run by run (common random numbers):
  mean difference of the position RMSE and its 95 % interval (m); below zero is better.

Figures are made without pyplot (no global state, nothing shown by itself); in a notebook
the returned figure is displayed, ``fig.savefig(path)`` writes it. ``ax=`` draws into an
existing axes instead (its figure is returned).
"""

from __future__ import annotations

import numpy as np

from replay.run import tables
from replay.trajectory.recorded import is_recorded
from replay.util.series import joined, line
from replay.tasks import role_input
from replay.util.errors import ReplayError


def _axes(ax, size=(7.0, 4.0)):
    if ax is not None:
        return ax.figure, ax
    # lazy: start-up, the Python API (replay.api) imports this module: matplotlib measured ~1.1 s
    from matplotlib.figure import Figure  # noqa: PLC0415

    fig = Figure(figsize=size, layout="constrained")
    return fig, fig.add_subplot()


def _geo(meta: dict, utm: bool):
    """(offset (2,), axis labels) for positions in the frame's local east/north metres."""
    crs, origin = meta.get("crs"), meta.get("origin")
    if utm and crs and origin is not None:
        code = str(crs) if str(crs).upper().startswith("EPSG") else f"EPSG:{crs}"
        off = np.asarray(origin, float)[:2]
        return off, (f"UTM easting [m] ({code})", f"UTM northing [m] ({code})")
    return np.zeros(2), ("east [m] (local)", "north [m] (local)")


def _en(p, axis_names=("x", "y")):
    """East and north columns of positions ``p`` (n, d) with axes ``axis_names``."""
    names = [a.lower() for a in axis_names]
    e = names.index("east") if "east" in names else 0
    n = names.index("north") if "north" in names else 1
    return p[:, [e, n]]


def plot_track(source, *, ax=None, utm: bool = True, run: int = 0, filters=None):
    """The track of a :class:`~replay.frame.Frame` (reference, GPS) or of an evaluation (reference and
    each filter's estimate in run ``run``), on UTM axes when geodetic (``utm=False``: local axes)."""
    fig, ax = _axes(ax, (6.5, 6.0))
    if hasattr(source, "results"):  # an Evaluation
        off, labels = _geo(source.frame_meta, utm)
        names = tuple(source.axis_names)
        truth = np.asarray(source.truths[run], float)
        first = next((r.records[run].problem for r in source.results if len(r.records) > run), None)
        if first is not None:  # where the reference is masked, no line (as the scorer skips it)
            truth = np.where(np.asarray(first.truth_valid, bool)[:, None], truth, np.nan)
        truth = _en(truth, names) + off
        t = np.asarray(first.t, float) if first is not None else np.arange(len(truth), dtype=float)
        truth = np.column_stack(line(t, truth[:, 0], truth[:, 1])[1:])  # held at GPS fixes only: not dots
        ax.plot(truth[:, 0], truth[:, 1], color="k", lw=3.0, label="reference")
        for res in [tables.result(source, f) for f in filters] if filters else source.results:
            problem = res.records[run].problem if len(res.records) > run else None
            if problem is None:
                continue
            x = res.estimates[run].x[:, list(problem.position_index)]
            p = _en(x, names) + off
            if is_recorded(res.name):  # NaN off its associated samples: a line through them, not dots
                p = np.column_stack(joined(problem.t, p[:, 0], p[:, 1])[1:])
            ax.plot(p[:, 0], p[:, 1], lw=1.0, label=res.name)
        ax.set_title(f"{source.config['dataset']}: run {run}")
    else:  # a Frame
        off, labels = _geo(source.meta, utm)
        ref = source.reference.get("position")
        if ref is not None:
            p = (
                _en(
                    np.where(ref.valid[:, None], np.asarray(ref.values, float).reshape(len(ref), -1), np.nan),
                    ref.components or ("x", "y"),
                )
                + off
            )
            ax.plot(p[:, 0], p[:, 1], color="k", lw=2.0, label="reference")
        gps = _gps(source)
        if gps is not None:
            p = _en(np.where(gps.valid[:, None], gps.values, np.nan), gps.components or ("x", "y")) + off
            ax.plot(p[:, 0], p[:, 1], ".", ms=2.0, color="tab:orange", label="GPS fixes")
        ax.set_title(str(source.meta.get("dataset") or source.meta.get("source") or "frame"))
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_aspect("equal", adjustable="datalim")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.legend(loc="best", fontsize="small")
    return fig


def _gps(frame):
    """The frame's GPS position channel (found by role, as the tasks do), or None."""
    try:
        found = role_input(frame, "gps", "plot_track")
    except ReplayError:
        return None
    ch = frame.channels.get(found.channels.get("position", "") if found else "")
    return ch if ch is not None and np.ndim(ch.values) == 2 else None


def plot_errors(ev, *, ax=None, filters=None):
    """Position error over time: RMSE across the runs at each step, one line per filter (m)."""
    fig, ax = _axes(ax)
    curves = tables.rmse_over_time(ev, filters=filters)
    for name in curves.columns:
        t, y = curves.index.to_numpy(), curves[name].to_numpy()
        t, y = (joined if is_recorded(name) else line)(t, y)
        ax.plot(t, y, lw=1.0, label=name)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"position error, RMSE over {ev.config['runs']} runs [m]")
    ax.set_title(f"{ev.config['dataset']}, task {ev.config['task']}")
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_rmse(ev, *, ax=None, metric: str = "pos_rmse"):
    """``metric`` per filter: mean over runs with its 95 % interval (error bars), m."""
    fig, ax = _axes(ax, (6.0, 3.5))
    rows = ev.rows
    mean = np.array([float(r.get(metric, np.nan)) for r in rows])
    ci = np.array([float(r.get(f"{metric}_ci95", np.nan)) for r in rows])
    pos = np.arange(len(rows))
    ax.bar(pos, mean, yerr=np.where(np.isfinite(ci), ci, 0.0), capsize=4, color="tab:blue", alpha=0.8)
    ax.set_xticks(pos, [r["label"] for r in rows], rotation=20)
    ax.set_ylabel(f"{metric} [{_unit(metric)}]")
    ax.set_title(f"mean over {ev.config['runs']} runs, 95 % interval")
    return fig


def plot_paired(ev, *, ax=None, metric: str = "pos_rmse"):
    """Each filter minus the baseline on the same runs: mean difference of ``metric`` and its 95 %
    interval (the leaderboard's ``<metric>_vs_<baseline>`` columns); below zero: better."""
    fig, ax = _axes(ax, (6.0, 3.5))
    col = next((k for r in ev.rows for k in r if k.startswith(f"{metric}_vs_") and not k.endswith("_ci95")), None)
    if col is None:
        raise ValueError(f"no paired {metric} column: the evaluation needs two filters or more")
    base = col[len(metric) + 4 :]
    rows = [r for r in ev.rows if r["label"] != base]
    diff = np.array([float(r[col]) for r in rows])
    ci = np.array([float(r[f"{col}_ci95"]) for r in rows])
    pos = np.arange(len(rows))
    ax.errorbar(diff, pos, xerr=np.where(np.isfinite(ci), ci, 0.0), fmt="o", capsize=4)
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_yticks(pos, [r["label"] for r in rows])
    ax.set_ylim(-0.6, len(rows) - 0.4)
    ax.set_xlabel(f"{metric} minus {base}'s, same runs [{_unit(metric)}]")
    ax.set_title(f"paired difference to {base}: mean and 95 % interval")
    return fig


def _unit(metric: str) -> str:
    if metric.startswith(("nees", "nis", "anees", "anis")):
        return "1"
    if metric.endswith("_pct"):
        return "%"
    if metric.startswith(("pitch", "yaw", "roll", "heading")):
        return "rad"
    return "m"
