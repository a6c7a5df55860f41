"""``replay score --plot`` and ``ScoreResult.plot()``: evo's figures, aligned as scored.

Figures (:data:`KINDS`), each a :class:`matplotlib.figure.Figure` made without pyplot:

* ``trajectories`` — left: the reference (the whole trajectory, one continuous line) and every
  estimate after its alignment, in the plot mode's plane (:data:`MODES`: xy, xz, yz, yx, zx, zy, or xyz in 3-D),
  equal scales; right, top: the APE of the pose relation over time, one line per estimate, with its
  RMSE as a dotted line; below it, when the RPE was computed, the RPE at the second pose of each pair;
* ``map`` — evo's error map: per estimate, the reference (dashed grey) and the aligned estimate
  drawn as a line coloured by its APE at each matched pose, with a colour bar in the APE's unit;
* ``xyz`` and ``rpy`` — evo_traj's panels: x, y, z (m) and roll, pitch, yaw (deg) over time of the
  reference and of each aligned estimate (:mod:`replay.trajectory.plot_series`; ``rpy`` only when
  both have orientations).

Time in seconds from the reference's first matched pose; every axis names its unit as ``name (unit)``
(the convention of :mod:`replay.outputs.plots`). ``--plot FILE`` writes the ``trajectories`` figure
to FILE and each other one beside it as ``<stem>_<kind><suffix>`` (:func:`paths`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from replay.trajectory.pose_error import UNITS
from replay.util.errors import ReplayError
from replay.trajectory.plot_series import REFERENCE, first_stamp
from replay.trajectory.plot_series import rpy as rpy_figure
from replay.trajectory.plot_series import xyz as xyz_figure
from replay.util import outfile
import logging


FORMATS = ("png", "pdf", "svg", "eps")  # the extensions --plot writes
KINDS = ("trajectories", "map", "xyz", "rpy")
MODES = {
    "xy": (0, 1),
    "xz": (0, 2),
    "yz": (1, 2),
    "yx": (1, 0),
    "zx": (2, 0),
    "zy": (2, 1),
    "xyz": (0, 1, 2),
}  # evo's --plot_mode: horizontal, vertical axis
NAMES = {
    "trans": "translation",
    "rot": "rotation part",
    "full": "full pose",
    "angle_deg": "rotation angle",
    "angle_rad": "rotation angle",
    "point_distance": "point distance",
    "point_distance_error_ratio": "point distance error ratio",
}


def label(kind: str, rel: str) -> str:
    """An error axis label with its unit, e.g. ``APE translation (m)`` (a ratio: ``(dimensionless)``)."""
    return f"{kind} {NAMES[rel]} ({UNITS[rel] or 'dimensionless'})"


def check_mode(mode: str) -> tuple:
    if mode not in MODES:
        raise ReplayError(f"plot mode {mode!r}: expected one of {', '.join(MODES)}")
    return MODES[mode]


def relation_of(s, relation):
    """The pose relation plotted for score ``s``: ``relation``, else its first one."""
    return relation or next(iter(s.ape or s.rpe))


def track_axes(fig, where, mode: str):
    """An axes for tracks in ``mode``: 2-D with equal scales and ``x (m)``-style labels, or 3-D."""
    cols = check_mode(mode)
    ax = fig.add_subplot(where, **({"projection": "3d"} if len(cols) == 3 else {}))
    names = "xyz"
    ax.set_xlabel(f"{names[cols[0]]} (m)")
    ax.set_ylabel(f"{names[cols[1]]} (m)")
    if len(cols) == 3:
        ax.set_zlabel("z (m)")
    else:
        ax.set_aspect("equal", adjustable="datalim")
    return ax


def _fit_3d(ax, *ps):
    """Equal scales on a 3-D axes (box aspect from the data's extent)."""
    p = np.vstack(ps)
    span = np.ptp(p, axis=0)
    ax.set_box_aspect(np.maximum(span, 1e-3 * max(span.max(), 1e-9)))


def draw_track(ax, p, cols, **kw):
    """Positions ``p`` (n, 3) in the coordinates ``cols``, one line; returns it."""
    (line,) = ax.plot(*(p[:, c] for c in cols), **kw)
    return line


def figure(reference, scores: dict, *, relation: str | None = None, mode: str = "xy"):
    """The ``trajectories`` figure of the full ``reference`` and ``scores`` {name: Score}."""
    # lazy: start-up, `replay score` imports this module and plots only on request: matplotlib measured ~1.1 s
    from matplotlib.figure import Figure  # noqa: PLC0415

    cols = check_mode(mode)
    with_rpe = any(s.rpe for s in scores.values())
    fig = Figure(figsize=(13.0, 6.0), layout="constrained")
    grid = fig.add_gridspec(2 if with_rpe else 1, 2, width_ratios=[1.1, 1.0])
    top = track_axes(fig, grid[:, 0], mode)
    draw_track(
        top, reference.p, cols, color=REFERENCE, ls="--", lw=1.2, label=f"reference ({reference.name})", gid="reference"
    )
    t0 = first_stamp(scores)
    err_ax = fig.add_subplot(grid[0, 1])
    rpe_ax = fig.add_subplot(grid[1, 1], sharex=err_ax) if with_rpe else None
    for c, (name, s) in enumerate(scores.items()):
        rel = relation_of(s, relation)
        line = draw_track(top, s.aligned.p, cols, lw=1.0, color=f"C{c}", label=name, gid=name)
        if rel in s.ape:
            err_ax.plot(s.reference.t - t0, s.ape[rel], lw=0.9, color=line.get_color(), label=name, gid=name)
            err_ax.axhline(
                float(np.sqrt(np.mean(s.ape[rel] ** 2))),
                color=line.get_color(),
                lw=0.8,
                ls=":",
                label=f"_{name} rmse",
                gid=f"{name} rmse",
            )
            err_ax.set_ylabel(label("APE", rel))
        if rpe_ax is not None and rel in s.rpe and s.rpe_pairs is not None:
            tj, err = rpe_times(s, rel, t0)
            rpe_ax.plot(tj, err, lw=0.9, color=line.get_color(), label=name, gid=name)
            rpe_ax.set_ylabel(label("RPE", rel))
    if len(cols) == 3:
        _fit_3d(top, reference.p, *(s.aligned.p for s in scores.values()))
    top.set_title(f"trajectories, {mode} (estimates aligned as scored)")
    top.legend(fontsize="small")
    (rpe_ax or err_ax).set_xlabel("time since the first matched pose (s)")
    err_ax.set_title("absolute pose error (dotted: RMSE)")
    if err_ax.lines:
        err_ax.legend(fontsize="small")
    else:  # an RPE-only relation (point_distance_error_ratio)
        err_ax.text(
            0.5, 0.5, f"no APE of {relation} (an RPE relation)", ha="center", va="center", transform=err_ax.transAxes
        )
        err_ax.set_yticks([])
    if rpe_ax is not None:
        rpe_ax.set_title("relative pose error, at the second pose of each pair")
    return fig


def rpe_times(s, rel: str, t0: float):
    """(times of the second pose of each pair, RPE of ``rel``), in time order; a relation that leaves
    out pairs (point_distance_error_ratio at zero reference distance) keeps the times of the others."""
    i, j = s.rpe_pairs
    err = s.rpe[rel]
    tj = s.reference.t[j] - t0
    if len(err) != len(tj):
        tj = tj[np.linalg.norm(s.reference.p[j] - s.reference.p[i], axis=1) != 0]
    order = np.argsort(tj, kind="stable")
    return tj[order], err[order]


def error_map(reference, scores: dict, *, relation: str | None = None, mode: str = "xy"):
    """The ``map`` figure: one panel per estimate, its aligned track coloured by its APE (colour bar)."""
    # lazy: start-up, `replay score` imports this module and plots only on request: matplotlib measured ~1.1 s
    from matplotlib.collections import LineCollection  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    cols = check_mode(mode)
    have = {name: s for name, s in scores.items() if relation_of(s, relation) in s.ape}
    if not have:
        raise ReplayError(f"plot: no APE of {relation!r} to colour the tracks by")
    n = len(have)
    fig = Figure(figsize=(6.2 * min(n, 3), 5.2 * -(-n // 3)), layout="constrained")
    grid = fig.add_gridspec(-(-n // 3), min(n, 3))
    for k, (name, s) in enumerate(have.items()):
        rel = relation_of(s, relation)
        ax = track_axes(fig, grid[k // 3, k % 3], mode)
        draw_track(
            ax,
            reference.p,
            cols,
            color=REFERENCE,
            ls="--",
            lw=0.9,
            label=f"reference ({reference.name})",
            gid="reference",
        )
        pts = s.aligned.p[:, cols]
        segs = np.stack([pts[:-1], pts[1:]], axis=1)
        err = s.ape[rel]
        if len(cols) == 3:
            # lazy: start-up, `replay score` imports this module and plots only on request: matplotlib measured ~1.1 s
            from mpl_toolkits.mplot3d.art3d import Line3DCollection as Lines  # noqa: PLC0415
        else:
            Lines = LineCollection
        lc = Lines(segs, cmap="jet", lw=2.0, gid=name, label=name)
        lc.set_array(err[1:])  # a segment's colour: the error at its end pose (evo's colour map)
        lc.set_clim(float(err.min()), float(err.max()))
        (ax.add_collection3d if len(cols) == 3 else ax.add_collection)(lc)
        if len(cols) == 3:
            _fit_3d(ax, reference.p, s.aligned.p)
        else:
            ax.autoscale_view()
        fig.colorbar(lc, ax=ax, label=label("APE", rel), shrink=0.85, pad=0.1 if len(cols) == 3 else 0.05)
        ax.set_title(f"{name}: APE along the track, {mode}")
        ax.legend(fontsize="small", loc="best")
    return fig


def figures(reference, scores: dict, *, relation: str | None = None, mode: str = "xy", kinds=KINDS) -> dict:
    """{kind: Figure} of the ``kinds`` (:data:`KINDS`) that have something to show: ``map`` needs an APE
    of the relation, ``rpy`` orientations in the reference and an estimate."""

    check_mode(mode)
    make = {
        "trajectories": lambda: figure(reference, scores, relation=relation, mode=mode),
        "map": lambda: (
            error_map(reference, scores, relation=relation, mode=mode)
            if any(relation_of(s, relation) in s.ape for s in scores.values())
            else None
        ),
        "xyz": lambda: xyz_figure(reference, scores),
        "rpy": lambda: (
            rpy_figure(reference, scores)
            if reference.q is not None and any(s.aligned.q is not None for s in scores.values())
            else None
        ),
    }
    out = {kind: make[kind]() for kind in kinds}
    return {kind: fig for kind, fig in out.items() if fig is not None}


def paths(path) -> dict:
    """{kind: path} ``--plot FILE`` writes: FILE for ``trajectories``, ``<stem>_<kind><suffix>`` beside it
    for the others (written only when the figure has something to show)."""
    p = Path(path)
    return {kind: p if kind == "trajectories" else p.with_name(f"{p.stem}_{kind}{p.suffix}") for kind in KINDS}


def write(
    path, reference, scores: dict, *, relation: str | None = None, mode: str = "xy", what: str = "--plot"
) -> tuple[list, list]:
    """Save :func:`figures` to :func:`paths` of ``path`` (format from the extension: :data:`FORMATS`),
    each atomically, creating missing parent directories; returns (paths written, paths removed: a
    figure of an earlier call that this one does not draw, e.g. ``_rpy`` without orientations, which
    would otherwise be taken for this call's). An unsupported extension or a write error is one line."""
    outfile.check(path, what, FORMATS)
    where, written = paths(path), []
    ps = logging.getLogger("matplotlib.backends.backend_ps")  # "no transparency" for every eps: rendered opaque
    level = ps.level
    ps.setLevel(logging.ERROR)
    try:
        figs = figures(reference, scores, relation=relation, mode=mode)
        for kind, fig in figs.items():
            p = outfile.check(where[kind], what, FORMATS)
            written.append(
                outfile.write(p, what, lambda tmp, f=fig, p=p: f.savefig(tmp, dpi=120, format=p.suffix.lower()[1:]))
            )
    finally:
        ps.setLevel(level)
    removed = [p for kind, p in where.items() if kind not in figs and p.is_file() and not p.is_symlink()]
    for p in removed:
        try:
            p.unlink()
        except OSError as e:
            raise ReplayError(
                f"{what} {p}: an earlier figure this call does not draw, and it cannot be removed ({e.strerror})"
            ) from None
    return written, removed
