"""``replay score --plot``: the trajectories (aligned as scored) and their errors over time, one figure.

Left: the reference and every estimate after its alignment, seen from above (x, y in m,
equal scales). Right, top: the APE of the first pose relation over time (its unit), one line per
estimate; below it, when the RPE was computed, the RPE over time at the second pose of each
pair. Time in seconds from the reference's first matched pose. Written without pyplot.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from replay.trajectory.pose_error import UNITS

FORMATS = ("png", "pdf", "svg", "eps")  # the extensions --plot writes
NAMES = {"trans": "translation", "rot": "rotation part", "full": "full pose", "angle_deg": "rotation angle",
         "angle_rad": "rotation angle", "point_distance": "point distance",
         "point_distance_error_ratio": "point distance error ratio"}


def _label(kind: str, rel: str) -> str:
    unit = UNITS[rel]
    return f"{kind} {NAMES[rel]}" + (f" [{unit}]" if unit else " [-]")


def figure(reference, scores: dict, *, relation: str | None = None):
    """A :class:`matplotlib.figure.Figure` of the full ``reference`` and ``scores`` {name: Score}."""
    from matplotlib.figure import Figure

    with_rpe = any(s.rpe for s in scores.values())
    fig = Figure(figsize=(13.0, 6.0), layout="constrained")
    grid = fig.add_gridspec(2 if with_rpe else 1, 2, width_ratios=[1.1, 1.0])
    top = fig.add_subplot(grid[:, 0])
    top.plot(reference.p[:, 0], reference.p[:, 1], color="0.3", ls="--", lw=1.2, label=f"reference ({reference.name})")
    t0 = min(s.reference.t[0] for s in scores.values())
    err_ax = fig.add_subplot(grid[0, 1])
    rpe_ax = fig.add_subplot(grid[1, 1], sharex=err_ax) if with_rpe else None
    for name, s in scores.items():
        rel = relation or next(iter(s.ape or s.rpe))
        (line,) = top.plot(s.aligned.p[:, 0], s.aligned.p[:, 1], lw=1.0, label=name)
        if rel in s.ape:
            err_ax.plot(s.reference.t - t0, s.ape[rel], lw=0.9, color=line.get_color(), label=name)
            err_ax.set_ylabel(_label("APE", rel))
        if rpe_ax is not None and rel in s.rpe and s.rpe_pairs is not None:
            i, j = s.rpe_pairs
            err = s.rpe[rel]
            tj = s.reference.t[j] - t0
            if len(err) != len(tj):  # point_distance_error_ratio leaves out pairs of zero distance
                tj = np.arange(len(err))
            order = np.argsort(tj, kind="stable")
            rpe_ax.plot(tj[order], err[order], lw=0.9, color=line.get_color(), label=name)
            rpe_ax.set_ylabel(_label("RPE", rel))
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m]")
    top.set_aspect("equal", adjustable="datalim")
    top.set_title("trajectories (estimates aligned as scored)")
    top.legend(fontsize="small")
    (rpe_ax or err_ax).set_xlabel("time since the first matched pose [s]")
    err_ax.set_title("absolute pose error")
    err_ax.legend(fontsize="small")
    if rpe_ax is not None:
        rpe_ax.set_title("relative pose error")
    return fig


def write(path, reference, scores: dict, *, relation: str | None = None, what: str = "--plot") -> Path:
    """Save :func:`figure` to ``path`` (format from the extension: :data:`FORMATS`), atomically,
    creating missing parent directories; an unsupported extension or a write error is one line."""
    from replay.util import outfile

    path = outfile.check(path, what, FORMATS)
    fig = figure(reference, scores, relation=relation)
    return outfile.write(path, what, lambda tmp: fig.savefig(tmp, dpi=120, format=path.suffix.lower()[1:]))
