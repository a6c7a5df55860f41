"""Boxplots of saved or fresh scores: ``replay score --trials-plot`` and ``replay res --plot``.

Panels (:func:`panels`): the APE of the first pose relation, the RPE (when computed) and, per ``--lengths``
length, the relative translation error (% of the length) and rotation error (deg/m), rpg_trajectory_evaluation's
boxplots. Each panel has one box per estimate (each trial of a trial set is one, coloured by its set);
``replay res --plot`` adds the APE over time above them. Written without pyplot.
"""

from __future__ import annotations

import numpy as np
from replay.trajectory.lengths import UNITS as REL_UNITS
from replay.trajectory.pose_error import UNITS
from replay.util import outfile
from replay.trajectory.archive import frames

# pandas (1.5 s to import, measured with `python -X importtime` on the 2-core machine under load) and
# matplotlib (1.3 s) are imported inside the functions that need them: `replay score` without tables,
# archives or plots, and every other command, load neither.

FORMATS = ("png", "pdf", "svg", "eps")


def _unit(u: str) -> str:
    return f" [{u}]" if u else " [-]"


def panels(tables: dict, relation: str, label=lambda name: name) -> list:
    """``[(title, {box label: values})]`` of the archive tables (``ape``, ``rpe``, ``lengths`` DataFrames)."""

    out = []
    for kind in ("ape", "rpe"):
        df = tables.get(kind)
        if df is not None and relation in df:
            out.append(
                (
                    f"{kind.upper()} {relation}{_unit(UNITS[relation])}",
                    {label(n): g[relation].dropna().to_numpy() for n, g in df.groupby("estimate", sort=False)},
                )
            )
    df = tables.get("lengths")
    if df is not None:
        for length, g in df.groupby("length", sort=False):
            for err in ("trans_perc", "rot_deg_per_m"):
                out.append(
                    (
                        f"length {length}: {err}{_unit(REL_UNITS[err])}",
                        {label(n): h[err].to_numpy() for n, h in g.groupby("estimate", sort=False)},
                    )
                )
    return out


def _group(name: str) -> str:
    return name.rsplit("/", 1)[0] if "/" in name else name


def figure(boxes: list, over_time=None):
    """A figure of the panels (:func:`panels`); ``over_time``: ``(ylabel, {name: (t, values)})`` drawn on top."""
    # lazy: start-up, `replay score` imports this module and plots only on request: matplotlib measured ~1.1 s
    from matplotlib.figure import Figure  # noqa: PLC0415

    n = len(boxes)
    ncols = min(3, max(n, 1))
    nrows = -(-n // ncols) + (1 if over_time else 0)
    fig = Figure(figsize=(4.6 * ncols, 3.6 * nrows), layout="constrained")
    grid = fig.add_gridspec(nrows, ncols)
    groups = list(dict.fromkeys(_group(k) for _, data in boxes for k in data))
    colors = {g: f"C{k % 10}" for k, g in enumerate(groups)}
    if over_time:
        ax = fig.add_subplot(grid[0, :])
        ylabel, series = over_time
        t0 = min(float(t[0]) for t, _ in series.values())
        for name, (t, v) in series.items():
            ax.plot(np.asarray(t) - t0, v, lw=0.9, label=name, color=colors.get(_group(name)))
        ax.set_xlabel("time since the first matched pose [s]")
        ax.set_ylabel(ylabel)
        ax.set_title("error over time")
        ax.legend(fontsize="small")
    for k, (title, data) in enumerate(boxes):
        r, c = divmod(k, ncols)
        ax = fig.add_subplot(grid[r + (1 if over_time else 0), c])
        names = list(data)
        art = ax.boxplot([data[m] for m in names], showfliers=False, patch_artist=True)
        for patch, m in zip(art["boxes"], names):
            patch.set_facecolor(colors[_group(m)])
            patch.set_alpha(0.6)
        ax.set_xticks(range(1, len(names) + 1), names, rotation=45, ha="right", fontsize="small")
        ax.set_title(title, fontsize="medium")
    return fig


def save(path, fig, what: str):

    path = outfile.check(path, what, FORMATS)
    return outfile.write(path, what, lambda tmp: fig.savefig(tmp, dpi=110, format=path.suffix.lower()[1:]))


def write(path, result, what: str = "--trials-plot"):
    """``replay score --trials-plot``: the boxplots of ``result`` (a ScoreResult)."""

    return save(path, figure(panels(frames(result), result.settings["relations"][0])), what)


def write_res(path, archives, what: str = "--plot"):
    """``replay res --plot``: the APE over time and the boxplots of every estimate of the archives."""

    boxes, series, ylabel = [], {}, ""
    for a in archives:
        rel = a.meta["settings"]["relations"][0]
        label = (lambda n, a=a: f"{a.shown}:{n}") if len(archives) > 1 else (lambda n: n)
        tables = {k: a.table(k) for k in ("ape", "rpe", "lengths")}
        for title, data in panels(tables, rel, label):
            for t, d in boxes:
                if t == title:
                    d.update(data)
                    break
            else:
                boxes.append((title, data))
        ylabel = f"APE {rel}{_unit(UNITS[rel])}"
        for n, g in tables["ape"].groupby("estimate", sort=False):
            series[label(n)] = (g["t"].to_numpy(), g[rel].to_numpy())
    return save(path, figure(boxes, (ylabel, series)), what)
