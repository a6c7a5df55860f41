"""The figures of the paper-003 reproduction (:mod:`.p003`): the x and y position error over time at
the printed setting, drawn with :mod:`replay.outputs.plots` (units on the axes, one panel per filter,
the Monte Carlo band of the runs)."""

from __future__ import annotations

import numpy as np

from .common5 import rmse_figures

AXES = (("x", "x position error", "m"), ("y", "y position error", "m"))


def run_errors(ev, i) -> dict[str, np.ndarray]:
    """Per-run absolute x and y position errors (runs, steps) of result ``i`` of ``ev`` (m)."""
    pos = np.abs(np.stack([np.asarray(e["position"], float) for e in ev.results[i].errors]))
    return {key: pos[:, :, j] for j, (key, _, _) in enumerate(AXES)}


def error_figures(t, errors: dict[str, dict[str, np.ndarray]], what: str) -> dict:
    """One figure per axis (:func:`replay.reproduce.common5.rmse_figures`). ``errors``: {filter label: run_errors}."""
    return rmse_figures(t, errors, AXES, f"003, {what}")


def plots(t, errors: dict, doc, what: str) -> list[str]:
    """Write ``003_rmse_<axis>.png`` beside ``doc`` (``errors``: {filter label: run_errors}); the
    Markdown lines that show them."""
    from replay.outputs.plots import save

    try:
        figs = error_figures(t, errors, what)
    except ImportError:
        return ["(plot skipped: matplotlib is not installed)", ""]
    doc.parent.mkdir(parents=True, exist_ok=True)
    out = []
    for key, name, _ in AXES:
        png = doc.parent / f"003_rmse_{key}.png"
        save(figs[key], png)
        out += [f"![{name} over time, {what}]({png.name})", ""]
    return out + [
        "One panel per filter: the RMSE over the runs at each step and the 5-95 % band of the runs' "
        "absolute errors; grey: the other filters' RMSE.",
        "",
    ]
