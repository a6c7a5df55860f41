"""The figures of the paper-001 reproduction (:mod:`.p001`): the error over time of each DVL mode
per quantity, and the AUKF's noise-mean estimates, drawn with :mod:`replay.outputs.plots` (units on
the axes, one panel per filter, the Monte Carlo band of the runs)."""

from __future__ import annotations

import numpy as np

from .common5 import command, rmse_figures

TRACK = {"bottom": "bottom-lock DVL", "water": "water-track DVL"}
TRACKS = tuple(TRACK)

# (key, axis name, unit): the quantities of the paper's Fig. 3-5 that the task scores
QUANTITIES = (
    ("north", "north error", "m"),
    ("east", "east error", "m"),
    ("depth", "depth error", "m"),
    ("vx", "forward velocity error", "m/s"),
)
FILTERS = (("UKF", 0, False), ("AUKF (paper)", 1, False), ("AUKF (Q̂, R̂)", 0, True))  # label, result, QR job
# (key, column, axis name, unit) of the AUKF's noise-mean estimates
TRACES = (
    ("p", 0, "p̂ depth", "m"),
    ("p", 1, "p̂ forward velocity", "m/s"),
    ("q", 0, "q̂ north", "m/step"),
    ("q", 1, "q̂ east", "m/step"),
)


def run_errors(ev, i) -> dict[str, np.ndarray]:
    """Per-run absolute errors (runs, steps) of result ``i`` of ``ev``: north, east, depth (m), vx (m/s)."""
    errs = ev.results[i].errors
    pos = np.abs(np.stack([np.asarray(x["position"], float) for x in errs]))
    out = {q: pos[:, :, j] for j, (q, _, _) in enumerate(QUANTITIES[:3])}
    out["vx"] = np.abs(np.stack([np.asarray(x["vx"], float) for x in errs]))
    return out


def error_figures(t, errors: dict[str, dict[str, np.ndarray]], what: str) -> dict:
    """One figure per quantity (:func:`replay.reproduce.common5.rmse_figures`).
    ``errors``: {filter label: run_errors}."""
    return rmse_figures(t, errors, QUANTITIES, f"001, {what}")


def traces_figure(t, histories: list[dict], what: str):
    """p̂ and q̂ of the paper's AUKF over time: median and 5-95 % band over the runs, one panel each."""
    from replay.outputs import plots
    from replay.outputs.palette import colour

    fig, axes = plots.figure(len(TRACES), 1, figsize=(8, 2.1 * len(TRACES) + 0.6), sharex=True)
    for ax, (key, j, name, unit) in zip(axes[:, 0], TRACES):
        v = np.stack([np.asarray(h[key], float)[:, j] for h in histories])
        plots.mc_band(ax, t[-v.shape[1] :], v, colour("aukf"), "AUKF (paper)")
        ax.set_ylabel(plots.label(name, unit))
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper left")
    axes[-1, 0].set_xlabel("t (s)")
    plots.suptitle(fig, f"001: AUKF noise-mean estimates, {what}: median and 5-95 % of {len(histories)} runs")
    fig.subplots_adjust(hspace=0.15)
    return fig


def plots(evs, doc):
    from replay.outputs.plots import save

    out = []
    try:
        doc.parent.mkdir(parents=True, exist_ok=True)
        for track in TRACKS:
            ev, qr = evs[f"{track} 0.5"], evs[f"{track} 0.5 QR"]
            errors = {label: run_errors(qr if is_qr else ev, i) for label, i, is_qr in FILTERS}
            figs = error_figures(ev.t, errors, f"{TRACK[track]}, current 0.5 m/s")
            for key, name, unit in QUANTITIES:
                png = doc.parent / f"001_{track}_0.5_{key}.png"
                save(figs[key], png)
                out += [f"![{name} over time, {TRACK[track]}]({png.name})", ""]
        png = doc.parent / "001_traces.png"
        traces = evs["traces"]
        save(
            traces_figure(traces.t, [e.info["history"] for e in traces.results[0].estimates], "bottom lock, 0.5 m/s"),
            png,
        )
        out += [
            f"![p̂ and q̂ of the paper's AUKF over time]({png.name})",
            "",
            "Traces of the paper's AUKF (bottom lock, 0.5 m/s): median and 5-95 % band over the runs of p̂ "
            "of the depth gauge and of the forward DVL, q̂ of north and east. Command: "
            f"`{command(traces)}`.",
            "",
        ]
    except ImportError:
        out += ["(plots skipped: matplotlib is not installed)", ""]
    return "\n".join(out)
