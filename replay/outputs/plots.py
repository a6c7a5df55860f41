"""Drawing helpers shared by the report and the reproductions: Monte Carlo bands, chi-square
bands, gaps, units, and the one-colour-per-filter rule (:mod:`replay.outputs.palette`).

Conventions (the report follows them; a reproduction's PNG should too):

* every axis label names its unit: :func:`label` (``"position error (m)"``);
* a Monte Carlo result is drawn as its centre line (median, mean or RMSE over runs) with
  the 5-95 % band of the runs and thin outlines at its edges (:func:`mc_band`), one filter per
  panel when several bands would overlap (:func:`mc_figure`);
* missing samples (NaN: a masked reference) and time gaps (a step above ``GAP`` times the
  median step) break the lines instead of being bridged (:func:`gaps`); a sparse track (a
  recorded estimate, NaN on every reference sample it was not associated with) is drawn through
  its associated samples, broken only at its own time gaps (:func:`joined`), not as dots, and
  so is any series whose finite samples are mostly isolated (:func:`line`: a reference held only
  at GPS fixes, the errors scored there);
* every artist drawn for a filter carries its label as ``gid`` and its palette colour, so
  that :func:`artist_colours` reads back, from the figures, which colours each filter got.

It imports nothing of replay but the palette (numpy, scipy, matplotlib without pyplot)::

    from replay.outputs.plots import mc_figure, save
    fig = mc_figure(t, {"ekf": err_ekf, "pf": err_pf}, "depth error", "m",
                    "Paper 001, dive 3: depth error over 100 runs", stat="rmse")
    save(fig, "docs/reproduction/001_depth.png")
"""

from __future__ import annotations

import warnings
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from replay.outputs.palette import BAND, CONTEXT, Palette
from replay.util.series import GAP, gaps, isolated, joined, line  # noqa: F401 -- the line-breaking rules, shared with replay.run

STAT = {"median": "median", "mean": "mean", "rmse": "RMSE"}


def figure(nrows: int = 1, ncols: int = 1, figsize=(8, 4.5), **kw):
    """(Figure, axes array (nrows, ncols)) made without pyplot: no backend is switched, no global
    figure is kept (nothing to close; in a notebook the returned figure displays itself)."""
    # lazy: 1.3 s to import (measured), only when a figure is drawn
    from matplotlib.figure import Figure  # noqa: PLC0415

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, squeeze=False, **kw)


def label(name: str, unit: str | None) -> str:
    """An axis label with its unit: ``label("position error", "m")`` -> ``position error (m)``."""
    return f"{name} ({unit})" if unit else name


@contextmanager
def _quiet():
    """No warnings for all-NaN columns (a step that no run scored: a gap, on purpose)."""
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def centre(values, stat: str = "median"):
    """The centre line over runs (axis 0) of a (runs, steps) array: median, mean or rmse."""
    v = np.asarray(values, float)
    with _quiet():
        if stat == "median":
            return np.nanmedian(v, axis=0)
        if stat == "mean":
            return np.nanmean(v, axis=0)
        if stat == "rmse":
            return np.sqrt(np.nanmean(v**2, axis=0))
    raise ValueError(f"stat {stat!r}: median, mean or rmse")


def quantiles(values, q=(5, 95)):
    """The ``q`` percentiles over runs (axis 0), NaN where no run has a value."""
    with _quiet():
        return np.nanpercentile(np.asarray(values, float), q, axis=0)


def mc_band(ax, t, values, color, name=None, q=(5, 95), stat="median", alpha=0.22, lw=1.3, join=False):
    """Centre line and ``q`` band (with thin outlines) of per-run values (runs, steps) against ``t``.

    Returns the centre line. ``name`` becomes every artist's ``gid`` (and the line's label).
    ``join``: a sparse track, drawn through its finite steps (:func:`joined`)."""
    values = np.atleast_2d(np.asarray(values, float))
    mid, (lo, hi) = centre(values, stat), quantiles(values, q)
    tt, mid, lo, hi = (joined if join else line)(t, mid, lo, hi)
    if len(values) > 1:
        band = ax.fill_between(tt, lo, hi, color=color, alpha=alpha, lw=0, gid=name)
        band.set_label(f"_{q[0]:g}-{q[1]:g} % of {len(values)} runs")
        for edge in (lo, hi):
            ax.plot(tt, edge, color=color, lw=0.5, alpha=0.8, gid=name)
    (centre_line,) = ax.plot(tt, mid, color=color, lw=lw, label=name, gid=name)
    return centre_line


def chi2_limits(dof, runs: int, p: float = 0.95):
    """Two-sided ``p`` band of the average of ``runs`` chi-square(``dof``) values (NaN where dof <= 0)."""
    # lazy: 1.0 s to import (measured), only for a chi-square band
    from scipy import stats  # noqa: PLC0415

    dof = np.asarray(dof, float)
    a = (1 - p) / 2
    with np.errstate(all="ignore"):
        k = np.where(dof > 0, dof * runs, np.nan)
        return stats.chi2.ppf(a, k) / runs, stats.chi2.ppf(1 - a, k) / runs


def chi2_band(ax, t, dof, runs: int, p: float = 0.95):
    """The ``p`` chi-square band of an average over ``runs`` runs: a horizontal span for one
    dof, else a band that follows the per-step dof (none where the dof is 0)."""
    dof = np.broadcast_to(np.asarray(dof, float), np.shape(t))
    valid = np.unique(dof[dof > 0])
    if not len(valid):
        return None
    text = f"{p * 100:g} % chi-square band, {runs} runs, dof {'/'.join(f'{d:g}' for d in valid[:4])}"
    if len(valid) == 1:
        lo, hi = chi2_limits(valid[0], runs, p)
        return ax.axhspan(lo, hi, color=BAND, alpha=0.25, lw=0, label=text, gid="chi2")
    lo, hi = chi2_limits(dof, runs, p)
    tt, lo, hi = gaps(t, lo, hi)
    return ax.fill_between(tt, lo, hi, color=BAND, alpha=0.25, lw=0, step="mid", label=text, gid="chi2")


def masked_spans(ax, t, valid, text="reference masked"):
    """Light hatched spans over the times where ``valid`` is False (nothing is scored there); none when
    the valid samples are mostly isolated (a reference held at GPS fixes only: sampled, not masked)."""
    t, valid = np.asarray(t, float), np.asarray(valid, bool)
    if valid.all() or not len(t) or isolated(valid):
        return
    edges = np.flatnonzero(np.diff(np.r_[0, (~valid).astype(int), 0]))
    for i, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
        ax.axvspan(
            t[a],
            t[min(b, len(t) - 1)],
            color="#f0f0f0",
            hatch="//",
            ec="#d0d0d0",
            lw=0,
            label=text if i == 0 else None,
            gid="masked",
            zorder=0,
        )


@dataclass(frozen=True)
class Panels:
    """How :func:`mc_figure` draws its panels: the centre line ``stat`` (median, mean or rmse: :data:`STAT`) and
    the ``q`` percentile band, a log y axis (``logy``), the colours (``palette``, default: one per label), the x
    axis label, the panels per row (``ncols``) and the labels of sparse tracks (``join``: :func:`joined`)."""

    stat: str = "median"
    q: tuple = (5, 95)
    logy: bool = False
    palette: Palette | None = None
    xlabel: str = "t (s)"
    ncols: int = 3
    join: tuple | list | set = ()


def mc_figure(t, curves: dict, name: str, unit: str | None, title: str, **panels):
    """One panel per filter: its centre line and ``q`` band over runs, the others' centre lines
    in grey for context; shared axes. ``curves``: {label: (runs, steps) values against ``t``}
    (signed or absolute errors; with ``stat="rmse"`` the line is the RMSE over the runs at each
    step and the band the ``q`` percentiles of the values themselves: pass absolute errors);
    ``panels``: the fields of :class:`Panels` (one record; an unknown name is a TypeError)."""
    o = Panels(**panels)
    stat, q, join, ncols = o.stat, o.q, o.join, o.ncols
    pal = o.palette or Palette(curves)
    n = len(curves)
    cols = min(n, ncols)
    rows = -(-n // cols)
    fig, axes = figure(rows, cols, figsize=(4.6 * cols + 0.6, 2.9 * rows + 0.7), sharex=True, sharey=True)
    mids = {lab: centre(v, stat) for lab, v in curves.items()}
    for ax, (lab, v) in zip(axes.flat, curves.items()):
        for other, m in mids.items():
            if other != lab:
                ax.plot(*(joined if other in join else line)(t, m), color=CONTEXT, lw=0.7, alpha=0.7)
        mc_band(ax, t, v, pal.colour(lab), lab, q=q, stat=stat, join=lab in join)
        runs = np.atleast_2d(v).shape[0]
        ax.set_title(
            f"{lab}: {STAT[stat]} over {runs} runs" + (f", band {q[0]:g}-{q[1]:g} %" if runs > 1 else ""), fontsize=9
        )
        if o.logy and (np.asarray(v, float) > 0).any():  # all zero (an estimate equal to the reference): linear
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel(label(name, unit))
    for ax in axes[-1, :]:
        ax.set_xlabel(o.xlabel)
    suptitle(fig, title)
    fig.subplots_adjust(hspace=0.3, wspace=0.06)
    return fig


def band_panels(t, panels, color, name: str, title: str):
    """A column of panels with a shared time axis, one per ``(axis name, unit, (runs, steps) values)``: the
    median and 5-95 % band over the runs (:func:`mc_band`, labelled ``name``) against the last ``steps``
    times of ``t`` (a series recorded from the first update on)."""
    fig, axes = figure(len(panels), 1, figsize=(8, 2.1 * len(panels) + 0.6), sharex=True)
    for ax, (axis, unit, values) in zip(axes[:, 0], panels):
        mc_band(ax, t[-values.shape[1] :], values, color, name)
        ax.set_ylabel(label(axis, unit))
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper left")
    axes[-1, 0].set_xlabel("t (s)")
    suptitle(fig, title)
    fig.subplots_adjust(hspace=0.15)
    return fig


def suptitle(fig, text: str):
    """The figure's title above its top edge (``save`` keeps it: the PNG is cropped to its content)."""
    fig.subplots_adjust(top=1 - 0.35 / fig.get_figheight())
    return fig.suptitle(text, y=1.0, va="bottom")


def save(fig, path, dpi: int = 100):
    """Write ``fig`` as a PNG (cropped to its content); returns the path."""
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    return path


def artist_colours(figures) -> dict:
    """{gid: set of '#rrggbb'} over every line, band, bar and marker of ``figures`` that carries a gid."""
    # lazy: matplotlib, as in figure()
    from matplotlib.colors import to_hex  # noqa: PLC0415

    out: dict[str, set] = {}

    def add(gid, c):
        if gid is None or c is None:
            return
        arr = np.asarray(c, dtype=object if isinstance(c, str) else float)
        cs = [c] if isinstance(c, str) or arr.ndim == 1 else list(arr)
        for x in cs:
            out.setdefault(gid, set()).add(to_hex(x, keep_alpha=False))

    for fig in figures:
        for ax in fig.axes:
            for a in ax.get_children():
                gid = a.get_gid()
                if gid is None:
                    continue
                if hasattr(a, "get_color") and not hasattr(a, "get_facecolor"):
                    add(gid, a.get_color())  # lines
                elif hasattr(a, "get_facecolor"):
                    add(gid, a.get_facecolor())  # bands, bars, markers
    return out


def rmse_curve(err: np.ndarray) -> np.ndarray:
    """RMSE across runs at each step of errors (runs, n): sqrt(mean_runs e²), NaN-aware."""
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.nanmean(err**2, axis=0))


def abs_errors(errors: list[dict], quantities) -> dict:
    """``{key: (runs, steps) absolute errors}`` of per-run error dicts (``FilterResult.errors``), one per quantity
    ``(key, name, unit, error[, column])``: ``|error|`` of each run, of its ``column`` when one is given (the
    input of :func:`rmse_figures`)."""
    out = {}
    for key, _, _, error, *column in quantities:
        e = np.abs(np.stack([np.asarray(run[error], float) for run in errors]))
        out[key] = e[:, :, column[0]] if column else e
    return out


def rmse_figures(t, errors: dict, quantities, title: str) -> dict:
    """One figure per quantity ``(key, name, unit, ...)`` (further entries ignored: those of :func:`abs_errors`):
    a panel per filter with the RMSE over the runs at each step (the papers' curves) and the 5-95 % band of the
    runs' absolute errors. ``errors``: {filter label: {key: (runs, steps) errors}}; ``title`` starts each
    figure's title."""
    figs = {}
    for key, name, unit, *_ in quantities:
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
