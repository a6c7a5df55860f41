"""The figures of one report section (a dataset x task), as matplotlib Figures.

:func:`section_figures` returns ``[(name, Figure)]``: ``trajectory`` (run 0 beside the worst
run), ``error`` (position error over time, one panel per configuration with its 5-95 %
band), ``metrics`` (one panel per leaderboard metric: mean and 95 % interval, with units),
and from a campaign ``nees`` and ``nis`` (average over runs per step against the 95 %
chi-square band). Every artist drawn for a configuration has its label as ``gid`` and its
colour from one :class:`~replay.outputs.palette.Palette` for the whole page.
"""

from __future__ import annotations

import numpy as np

from replay.outputs import plots
from replay.outputs.palette import REFERENCE, Palette
from replay.outputs.report_data import Section, worst_run

CLIP = (1e-3, 1e6)  # NEES of a collapsed particle cloud reaches 1e190: keep the axes readable

# leaderboard metrics drawn in the metrics figure: column, name, unit
METRICS = [
    ("pos_rmse", "position RMSE", "m"),
    ("ate", "ATE (aligned)", "m"),
    ("final_err", "final error", "m"),
    ("drift_pct", "drift", "% of distance"),
    ("heading_rmse", "heading RMSE", "rad"),
    ("yaw_rmse", "yaw RMSE", "rad"),
    ("pitch_rmse", "pitch RMSE", "rad"),
    ("roll_rmse", "roll RMSE", "rad"),
    ("us_per_step", "filter time per step", "µs"),
]
_H = {"east": 0, "x": 0, "north": 1, "y": 1}


def _f(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _stack(runs: dict, key: str, fn=None):
    """(runs, n) of a per-step series over the runs (cut to the shortest), and the time axis."""
    series = list(runs.values())
    n = min(len(s["t"]) for s in series)
    vals = np.stack([(fn(s[key]) if fn else s[key])[:n] for s in series])
    return vals, series[0]["t"][:n]


def _plane_axes(names) -> tuple[int, int]:
    """(horizontal, vertical) position components for a plane view: east/x right, north/y up."""
    names = [str(a).lower() for a in names]
    h = [i for i, a in enumerate(names) if _H.get(a) == 0]
    v = [i for i, a in enumerate(names) if _H.get(a) == 1]
    return (h[0], v[0]) if h and v else (0, 1)


def _views(sec: Section):
    """[(run, title)]: the first run, and the worst run when it is another."""
    first = min(min(r) for r in sec.runs.values())
    worst = worst_run(sec)
    if worst == first:
        return [(first, f"run {first}, also the worst run")]
    views = [(first, f"run {first}")]
    if worst is not None:
        views.append((worst, f"worst run: {worst} (highest median position RMSE)"))
    return views


def _reference(sec: Section, run: int) -> dict:
    """The run's reference: a series that holds it whole (NaN where masked: a filter's, or any from a
    campaign), else (an eval directory of recorded estimates only: known where they were associated)
    the union of theirs, ``sparse`` (drawn joined, no masked spans)."""
    have = [(lab, runs[run]) for lab, runs in sec.runs.items() if run in runs]
    dense = [s for _, s in have if not s.get("ref_sparse")]
    if dense:  # valid: where the reference is (a recorded estimate's own series is valid where associated)
        return {**dense[0], "valid": np.isfinite(dense[0]["ref"]).all(axis=1), "sparse": False}
    n = min(len(s["t"]) for _, s in have)
    ref = np.full_like(have[0][1]["ref"][:n], np.nan)
    for _, s in have:
        ref = np.where(np.isfinite(ref), ref, s["ref"][:n])
    return {"t": have[0][1]["t"][:n], "ref": ref, "valid": np.isfinite(ref).all(axis=1), "sparse": True}


def _estimates(ax, sec: Section, pal: Palette, run: int, cols, ref):
    """The run's estimates of components ``cols`` (one: against time), then the reference on top; a
    recorded estimate (and a reference known only where they were associated) through its associated
    samples (:func:`replay.outputs.plots.joined`)."""
    for lab, runs in sec.runs.items():
        if run in runs:
            s = runs[run]
            xy = (plots.joined if lab in sec.sparse else plots.line)(s["t"], *(s["pos"][:, c] for c in cols))
            ax.plot(*xy[-2:], lw=1, label=lab, gid=lab, **_still(xy[-2:]), **pal.style(lab))
    xy = (plots.joined if ref["sparse"] else plots.line)(ref["t"], *(ref["ref"][:, c] for c in cols))
    ax.plot(
        *xy[-2:],
        color=REFERENCE,
        lw=1.1,
        ls=(0, (4, 2)),
        label="reference",
        gid="reference",
        zorder=5,
        **_still(xy[-2:]),
    )


def _still(xy) -> dict:
    """A marker for a track that does not move in the plane (a line of no length draws nothing: a
    recording whose x and y are 0 throughout, e.g. an AR.Drone's raw odometry)."""
    pts = np.column_stack(xy)
    ok = np.flatnonzero(np.isfinite(pts).all(axis=1))
    if not len(ok) or np.ptp(pts[ok], axis=0).max() > 0:
        return {}
    return {"marker": "o", "ms": 6, "mfc": "none", "markevery": [int(ok[0])]}


def trajectory(sec: Section, pal: Palette):
    """Run 0 beside the worst run: the horizontal plane (two or three axes) and each other
    component over time (one or three axes)."""
    views, d = _views(sec), len(sec.axes)
    plane = _plane_axes(sec.axes) if d >= 2 else None
    timed = [i for i in range(d) if plane is None or (d == 3 and i not in plane)]
    heights = [1.8] * (plane is not None) + [1] * len(timed)
    fig, axes = plots.figure(
        len(heights),
        len(views),
        figsize=(6.4 * len(views), 2.6 * sum(heights) + 0.6),
        gridspec_kw={"height_ratios": heights},
    )
    for c, (run, what) in enumerate(views):
        ref = _reference(sec, run)
        row = 0
        if plane is not None:
            h, v = plane
            ax = axes[0, c]
            _estimates(ax, sec, pal, run, (h, v), ref)
            still = all(ln.get_marker() == "o" for ln in ax.lines)
            ax.set(
                xlabel=plots.label(sec.axes[h], "m"),
                ylabel=plots.label(sec.axes[v], "m"),
                title=f"{sec.axes[h]}-{sec.axes[v]} plane, {what}" + (" (no motion in it)" if still else ""),
            )
            ax.set_aspect("equal", adjustable="datalim")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
            row = 1
        for k, i in enumerate(timed):
            ax = axes[row + k, c]
            if not ref["sparse"]:  # else unknown: NaN there means "not associated"
                plots.masked_spans(ax, ref["t"], ref["valid"])
            _estimates(ax, sec, pal, run, (i,), ref)
            ax.set(xlabel="t (s)", ylabel=plots.label(sec.axes[i], "m"), title=f"{sec.axes[i]} over time, {what}")
            if str(sec.axes[i]).lower() in ("depth", "down"):
                ax.invert_yaxis()
            ax.grid(alpha=0.3)
            if plane is None:
                ax.legend(fontsize=7)
    plots.suptitle(fig, f"{sec.title}: trajectories (reference dashed black)")
    fig.subplots_adjust(hspace=0.45, wspace=0.25)
    return fig


def error(sec: Section, pal: Palette):
    curves, t = {}, None
    for lab, runs in sec.runs.items():
        curves[lab], tt = _stack(runs, "err", lambda e: np.sqrt(np.sum(e**2, axis=1)))
        t = tt if t is None or len(tt) < len(t) else t
    curves = {lab: v[:, : len(t)] for lab, v in curves.items()}
    fig = plots.mc_figure(
        t,
        curves,
        "position error",
        "m",
        f"{sec.title}: position error over time (median and 5-95 % of the runs per filter; "
        "grey: the other filters' medians)",
        logy=True,
        palette=pal,
        join=sec.sparse,
    )
    dense = [s for runs in sec.runs.values() for s in runs.values() if not s.get("ref_sparse")]
    valid = np.isfinite(dense[0]["ref"]).all(axis=1) if dense else None  # eval, recorded only: unknown
    for ax in fig.axes:
        if ax.get_visible() and valid is not None:
            plots.masked_spans(ax, t, valid[: len(t)])
    fig.axes[0].legend(fontsize=7, loc="upper left")
    return fig


def metrics(sec: Section, pal: Palette):
    rows = [r for r in sec.rows if r.get("label") in sec.runs] or sec.rows
    have = [m for m in METRICS if any(np.isfinite(_f(r.get(m[0]))) for r in rows)]
    if not have or not rows:
        return None
    cols = min(len(have), 3)
    nrow = -(-len(have) // cols)
    fig, axes = plots.figure(nrow, cols, figsize=(4.6 * cols + 1.2, (0.32 * len(rows) + 1.3) * nrow))
    y = np.arange(len(rows))[::-1]
    for ax, (col, name, unit) in zip(axes.flat, have):
        for yi, r in zip(y, rows):
            v, ci, lab = _f(r.get(col)), _f(r.get(f"{col}_ci95")), str(r.get("label"))
            if not np.isfinite(v):
                ax.text(0.02, yi, "no value", transform=ax.get_yaxis_transform(), va="center", fontsize=7, color="0.4")
                continue
            c = pal.colour(lab)
            if np.isfinite(ci):
                ax.plot([v - ci, v + ci], [yi, yi], color=c, lw=2.2, solid_capstyle="butt", gid=lab)
            ax.plot([v], [yi], "o", color=c, ms=5, gid=lab)
            if col == "pos_rmse" and _f(r.get("lost")) > 0:
                ax.annotate(
                    f" lost {int(_f(r['lost']))}/{int(_f(r.get('runs')))}",
                    (v, yi),
                    fontsize=7,
                    va="bottom",
                    color="0.3",
                )
        ax.set_yticks(y, [str(r.get("label")) for r in rows], fontsize=8)
        ax.set_ylim(-0.7, len(rows) - 0.3)
        ax.set_xlabel(plots.label(name, unit))
        ax.set_title(
            name + (": median per step" if col == "us_per_step" else ": mean over runs, 95 % interval"), fontsize=9
        )
        vals = [_f(r.get(col)) for r in rows]
        vals = [v for v in vals if np.isfinite(v) and v > 0]
        if vals and max(vals) / min(vals) > 50:
            ax.set_xscale("log")
        ax.grid(axis="x", alpha=0.3)
    for ax in axes.flat[len(have) :]:
        ax.set_visible(False)
    plots.suptitle(fig, f"{sec.title}: leaderboard metrics")
    fig.subplots_adjust(hspace=0.6, wspace=0.45)
    return fig


def _consistency(sec: Section, pal: Palette, key: str, flags: dict):
    have = {
        lab: runs
        for lab, runs in sec.runs.items()
        if all(key in s for s in runs.values()) and any(np.isfinite(s[key]).any() for s in runs.values())
    }
    if not have:
        return None
    fig, ax = plots.figure(figsize=(12, 4.4))
    ax = ax[0, 0]
    counts, clipped = [], False
    for lab, runs in have.items():
        vals, t = _stack(runs, key)
        avg = plots.centre(vals, "mean")
        clipped |= bool(np.any((avg < CLIP[0]) | (avg > CLIP[1])))
        tt, avg = plots.line(t, np.clip(avg, *CLIP))
        flag = flags.get(lab, "")
        ax.plot(
            tt,
            avg,
            lw=1,
            label=lab + (f" ({flag})" if flag and flag != "consistent" else ""),
            gid=lab,
            **pal.style(lab),
        )
        counts.append(len(vals))
    runs_n = max(set(counts), key=counts.count)
    if key == "nees":
        dof, t = len(sec.axes), next(iter(next(iter(have.values())).values()))["t"]
    else:
        dofs, t = _stack(next(iter(have.values())), "nis_dof")
        dof = dofs[0]
    plots.chi2_band(ax, t, dof, runs_n)
    what = f"position, d = {len(sec.axes)}" if key == "nees" else "innovation, d per step"
    ax.set(
        xlabel="t (s)",
        ylabel=plots.label(f"average {key.upper()} over runs", "dimensionless"),
        yscale="log",
        title=f"{sec.title}: {key.upper()} ({what}) against the 95 % chi-square band"
        + (f" (values clipped to [{CLIP[0]:g}, {CLIP[1]:g}])" if clipped else ""),
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def section_figures(sec: Section, pal: Palette) -> list:
    """``[(name, Figure)]`` of one section (figures that have nothing to show are left out)."""
    flags = {str(r.get("label")): r for r in sec.rows}
    out = [
        ("trajectory", trajectory(sec, pal)),
        ("error", error(sec, pal)),
        ("metrics", metrics(sec, pal)),
        ("nees", _consistency(sec, pal, "nees", {k: r.get("anees_flag", "") for k, r in flags.items()})),
        ("nis", _consistency(sec, pal, "nis", {k: r.get("anis_flag", "") for k, r in flags.items()})),
    ]
    return [(name, fig) for name, fig in out if fig is not None]
