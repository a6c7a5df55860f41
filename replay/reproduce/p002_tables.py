"""Tables of the paper-002 reproduction: position-error definitions, per-filter rows, Fig. 9.

Used by :mod:`replay.reproduce.p002`; every function takes an evaluation (the
result of :func:`replay.evaluate.evaluate`) and returns numbers or Markdown lines.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from replay.score import ci95

COLS = ("position", "x", "y", "pitch", "yaw")


# --- position-error definitions ------------------------------------------------------
def position_definitions(errors: list[np.ndarray]) -> dict[str, np.ndarray]:
    """Per-run values of each candidate definition from per-run (n, 3) error arrays."""
    out = {"rmse3": [], "rmse2": [], "mean3": [], "mean2": []}
    for e in errors:
        e = e[np.isfinite(e).all(axis=1)]
        d3, d2 = np.sum(e**2, axis=1), np.sum(e[:, :2] ** 2, axis=1)
        out["rmse3"].append(np.sqrt(d3.mean()))
        out["rmse2"].append(np.sqrt(d2.mean()))
        out["mean3"].append(np.sqrt(d3).mean())
        out["mean2"].append(np.sqrt(d2).mean())
    return {k: np.array(v) for k, v in out.items()}


DEFINITIONS = {
    "rmse3": "3-D RMSE sqrt(mean_k |e_k|^2) = sqrt(X^2+Y^2+Z^2) (the scorer's pos_rmse)",
    "rmse2": "horizontal RMSE sqrt(mean_k (ex^2+ey^2)) = sqrt(X^2+Y^2)",
    "mean3": "mean over steps of the 3-D Euclidean error |e_k|",
    "mean2": "mean over steps of the horizontal Euclidean error",
}


# --- one table -----------------------------------------------------------------------
def cell(values):
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return (float(v.mean()) if len(v) else float("nan")), ci95(v)


def table_rows(ev, paper: dict, reference: str | None = "igwo-stcpf"):
    """Rows: filter, then per column (paper, ours, ci, ratio), plus paired Δ of position vs ``reference``."""
    per = {}
    for r in ev.results:
        ok = [i for i, m in enumerate(r.runs) if not m["diverged"]]
        pos = position_definitions([r.errors[i]["position"] for i in ok])
        runs = [r.runs[i] for i in ok]
        per[r.name] = {"position": pos["rmse3"], "defs": pos,
                       "x": np.array([m["x_rmse"] for m in runs]), "y": np.array([m["y_rmse"] for m in runs]),
                       "pitch": np.array([m.get("pitch_rmse", np.nan) for m in runs]),
                       "yaw": np.array([m.get("yaw_rmse", np.nan) for m in runs]),
                       "diverged": len(r.runs) - len(ok), "us": r.summary["us_per_step"], "ok": ok}
    rows = []
    for name, p in per.items():
        row = {"filter": name, "diverged": p["diverged"], "runs": len(p["ok"]) + p["diverged"], "us": p["us"],
               "defs": {k: cell(v) for k, v in p["defs"].items()}}
        for j, col in enumerate(COLS):
            mean, ci = cell(p[col])
            pv = paper.get(name, (np.nan,) * 5)[j]
            row[col] = (pv, mean, ci, mean / pv if pv == pv else np.nan)
        if reference in per and name != reference:
            a = dict(zip(p["ok"], p["position"]))
            b = dict(zip(per[reference]["ok"], per[reference]["position"]))
            both = sorted(set(a) & set(b))
            row["paired"] = cell([a[i] - b[i] for i in both])
        rows.append(row)
    return rows


def fmt(x, digits=4):
    return "nan" if not np.isfinite(x) else f"{x:.{digits}f}"


def md_table(rows, title: str, command: str, note: str = "") -> list[str]:
    head = ["filter"] + [f"{c} paper / ours ± 95 % / ratio" for c in COLS] + \
        ["Δ position vs IGWO-STCPF (paired) ± 95 %", "µs/step", "diverged"]
    lines = [f"### {title}", "", f"`{command}`", ""]
    if note:
        lines += [note, ""]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["filter"]]
        for c in COLS:
            pv, mean, ci, ratio = r[c]
            cells.append(f"{fmt(pv)} / {fmt(mean)} ± {fmt(ci)} / {fmt(ratio, 2)}")
        pd = r.get("paired")
        cells.append(f"{fmt(pd[0])} ± {fmt(pd[1])}" if pd else "—")
        cells += [f"{r['us']:.0f}", f"{r['diverged']}/{r['runs']}"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def print_rows(rows, title):
    print(f"\n== {title}")
    print(f"{'filter':12s} " + "  ".join(f"{c:>30s}" for c in COLS))
    for r in rows:
        cells = []
        for c in COLS:
            pv, mean, ci, ratio = r[c]
            cells.append(f"{fmt(pv):>7s} {fmt(mean):>7s}±{fmt(ci):6s} x{fmt(ratio, 2):>5s}")
        print(f"{r['filter']:12s} " + "  ".join(f"{x:>30s}" for x in cells))


# --- Monte Carlo convergence (Fig. 9) ------------------------------------------------
def first_runs(ev, n: int):
    """The evaluation restricted to its first ``n`` runs: the numbers of an ``n``-run evaluation
    (each run's seeds depend only on (seed, run)); :meth:`replay.evaluate.Evaluation.first`."""
    return ev.first(n)


def convergence(ev, png: Path) -> list[str]:
    """Fig. 9: per-run position RMSE against the Monte Carlo trial index, and its running mean."""
    n = ev.config["runs"]
    marks = [m for m in (10, 50, 100, 200, 500, n) if m <= n]
    marks = sorted(set(marks))
    lines = [f"### Convergence over Monte Carlo trials (Fig. 9): {n} runs, Table 5 setup", "",
             "Running mean of the per-run position RMSE (m) after the first m runs ± 95 % "
             "(diverged runs left out); the same runs as Table 5 (its first 100).", "",
             "| filter | " + " | ".join(f"m = {m}" for m in marks) + " |", "|" + "---|" * (len(marks) + 1)]
    series = {}
    for r in ev.results:
        v = np.array([np.nan if m["diverged"] else m["pos_rmse"] for m in r.runs])
        series[r.name] = v
        lines.append(f"| {r.name} | " + " | ".join(f"{fmt(cell(v[:m])[0])} ± {fmt(cell(v[:m])[1])}"
                                                   for m in marks) + " |")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return lines + ["", "(plot skipped: matplotlib is not installed)", ""]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    idx = np.arange(1, n + 1)
    for name, v in series.items():
        ok = np.isfinite(v)
        run_mean = np.cumsum(np.where(ok, v, 0.0)) / np.maximum(np.cumsum(ok), 1)
        line, = ax.plot(idx, run_mean, lw=2, label=name)
        ax.plot(idx[ok], v[ok], ".", ms=2, alpha=0.3, color=line.get_color())
    ax.set_yscale("log")
    ax.set_xlabel("Monte Carlo trial")
    ax.set_ylabel("position RMSE (m): per trial (dots), running mean (lines)")
    ax.set_title(f"paper 002, sim/auv-sonar, Table 5 setup, {n} trials")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return lines + ["", f"![convergence]({png.name})", ""]
