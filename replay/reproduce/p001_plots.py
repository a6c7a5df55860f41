"""The figures of the paper-001 reproduction (:mod:`.p001`): RMSE over time per DVL reading, AUKF traces."""
from __future__ import annotations

import numpy as np

from .common5 import command, plot_curves, rmse_curve
from .p001_plan import TRACK, TRACKS


def plots(evs, doc, strengths):
    out = []
    try:
        for track in TRACKS:
            ev, qr = evs[f"{track} 0.5"], evs[f"{track} 0.5 QR"]
            curves = {}
            for name, (e, i) in (("UKF", (ev, 0)), ("AUKF (paper)", (ev, 1)), ("AUKF (Q̂, R̂)", (qr, 0))):
                errs = e.results[i].errors
                pos = np.stack([x["position"] for x in errs])
                c = {ax: rmse_curve(pos[:, :, j]) for j, ax in enumerate(("north", "east", "depth"))}
                c["vx"] = rmse_curve(np.stack([x["vx"] for x in errs]))
                curves[name] = c
            png = doc.parent / f"001_{track}_0.5.png"
            plot_curves(png, ev.t, curves, ["north", "east", "depth", "vx"], "RMSE",
                        f"001: {TRACK[track]}, current 0.5 m/s")
            out += [f"![RMSE over time, {TRACK[track]}]({png.name})", ""]
        png = doc.parent / "001_traces.png"
        plot_traces(png, evs["traces"].t, [e.info["history"] for e in evs["traces"].results[0].estimates])
        out += [f"![p̂ and q̂ of the paper's AUKF over time]({png.name})", "",
                "Traces of the paper's AUKF (bottom lock, 0.5 m/s), one line per run: p̂ of the depth gauge and "
                "of the forward DVL, q̂ of north and east. Command: "
                f"`{command(evs['traces'])}`.", ""]
    except ImportError:
        out += ["(plots skipped: matplotlib is not installed)", ""]
    return ["## Plots", ""] + out


def plot_traces(path, t, histories):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("p", 0, "p̂ depth (m)"), ("p", 1, "p̂ vx (m/s)"), ("q", 0, "q̂ north (m/step)"),
              ("q", 1, "q̂ east (m/step)")]
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 8), sharex=True)
    for ax, (key, j, label) in zip(axes, panels):
        for h in histories[:10]:
            v = h[key][:, j]
            ax.plot(t[-len(v):], v, lw=0.7)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_title("001: AUKF noise-mean estimates (bottom lock, 0.5 m/s)")
    axes[-1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
