"""``replay report DIR``: figures and one self-contained HTML page for a result directory.

Works on a campaign directory (``units/``, :mod:`replay.campaign.store`) and on
a ``replay eval`` output directory (``estimates/<filter>.csv.gz``,
``leaderboard.csv``, ``manifest.json``; see :mod:`replay.outputs.files`). For each
dataset x task it draws, with matplotlib's non-interactive Agg backend:

* ``trajectory_<n>.png`` — reference and estimates (run 0) in the horizontal
  plane, and the vertical component over time;
* ``error_<n>.png`` — position error norm over time: median over runs and the
  5-95 % Monte Carlo band per filter;
* ``rmse_<n>.png`` — position RMSE per filter (mean over runs) with its 95 % interval;
* ``consistency_<n>.png`` — average NEES (and NIS) over runs per step against
  the 95 % chi-square band (campaigns only: an eval directory stores only the
  covariance diagonal).

``report.html`` embeds the PNGs (base64) and the leaderboard table: one file to
send or archive.
"""
from __future__ import annotations

import base64
import csv
import gzip
import html
import json
from pathlib import Path

import numpy as np

from replay import summary
from replay.util.errors import ReplayError

AXES = ("x", "y", "z")


def _load_campaign(d: Path):
    from replay.campaign import board
    from replay.campaign.store import Store

    store = Store(d)
    rows = board.read_dir(d)
    label = {r["config_hash"]: r["label"] for r in rows}
    groups = {}
    for h, cfg in store.configs():
        runs = [r["run"] for r in store.records(h) if r["status"] == "done"]
        if not runs:
            continue
        series = [store.series(h, r) for r in runs]
        g = groups.setdefault((cfg["dataset"], cfg["task"]), {})
        g[label.get(h, cfg["filter"])] = series
    return groups, rows


def _load_eval(d: Path):
    from replay.campaign.board import read_dir

    rows = read_dir(d)
    try:
        cfg = json.loads((d / "manifest.json").read_text())["config"]
        key = (cfg["dataset"], cfg["task"])
    except (OSError, KeyError, json.JSONDecodeError):
        key = (rows[0].get("dataset", "?"), rows[0].get("task", "?")) if rows else ("?", "?")
    filters = {}
    for path in sorted((d / "estimates").glob("*.csv.gz")):
        with gzip.open(path, "rt") as fh:
            head = fh.readline().strip().split(",")
            data = np.loadtxt(fh, delimiter=",", ndmin=2)
        col = {name: data[:, i] for i, name in enumerate(head)}
        runs = []
        for r in np.unique(col["run"]):
            sel = col["run"] == r
            s = {"t": col["t"][sel]}
            for j, a in enumerate(AXES):
                s[f"x{j}"] = col[f"x{j}"][sel]
                s[f"err_{a}"] = col[f"err_{a}"][sel]
                s[f"ref_{a}"] = s[f"x{j}"] - s[f"err_{a}"]
            runs.append(s)
        filters[path.name[:-len(".csv.gz")]] = runs
    for r in rows:
        r.setdefault("label", r.get("filter"))
    return {key: filters} if filters else {}, rows


def _png(fig, path: Path) -> Path:
    fig.savefig(path, dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


def _trajectory(plt, title, filters, path):
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.6))
    first = next(iter(filters.values()))[0]
    a.plot(first["ref_x"], first["ref_y"], "k-", lw=2.2, label="reference")
    b.plot(first["t"], first["ref_z"], "k-", lw=2.2, label="reference")
    for name, runs in filters.items():
        s = runs[0]
        a.plot(s["x0"], s["x1"], lw=1, label=name)
        b.plot(s["t"], s["x2"], lw=1, label=name)
    a.set(xlabel="x / east (m)", ylabel="y / north (m)", title=f"{title}: horizontal plane (run 0)")
    a.axis("equal")
    b.set(xlabel="t (s)", ylabel="z / up (m)", title="vertical over time (run 0)")
    a.legend(fontsize=8)
    return _png(fig, path)


def _error(plt, title, filters, path):
    fig, ax = plt.subplots(figsize=(12, 4.2))
    for name, runs in filters.items():
        n = min(len(s["t"]) for s in runs)
        e = np.stack([np.sqrt(sum(s[f"err_{a}"][:n] ** 2 for a in AXES)) for s in runs])
        t = runs[0]["t"][:n]
        with np.errstate(all="ignore"), _quiet():
            med = np.nanmedian(e, axis=0)
            lo, hi = np.nanpercentile(e, [5, 95], axis=0)
        line, = ax.plot(t, med, lw=1.2, label=f"{name} (median of {len(runs)} runs)")
        ax.fill_between(t, lo, hi, color=line.get_color(), alpha=0.2, lw=0)
    ax.set(xlabel="t (s)", ylabel="position error (m)", title=f"{title}: error over time, 5-95 % band over runs")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    return _png(fig, path)


def _rmse(plt, title, rows, path):
    rows = [r for r in rows if np.isfinite(_f(r.get("pos_rmse")))]
    fig, ax = plt.subplots(figsize=(max(5, 1.2 * len(rows) + 2), 4))
    x = np.arange(len(rows))
    ci = [_f(r.get("pos_rmse_ci95")) for r in rows]
    ax.bar(x, [_f(r["pos_rmse"]) for r in rows], yerr=[c if np.isfinite(c) else 0 for c in ci], capsize=4,
           color="tab:blue", alpha=0.75)
    ax.set_xticks(x, [str(r.get("label") or r.get("filter")) for r in rows], rotation=20, ha="right")
    ax.set(ylabel="position RMSE (m)", title=f"{title}: mean per-run RMSE, 95 % interval")
    return _png(fig, path)


CLIP = (1e-3, 1e6)  # NEES of a collapsed particle cloud reaches 1e190: keep the axes readable


def _consistency(plt, title, filters, path):
    from replay.metrics import chi2_band

    have = {k: v for k, v in filters.items() if "nees" in v[0]}
    if not have:
        return None
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.2))
    for name, runs in have.items():
        n = min(len(s["nees"]) for s in runs)
        t = runs[0]["t"][:n]
        with np.errstate(all="ignore"), _quiet():
            nees = np.nanmean(np.stack([s["nees"][:n] for s in runs]), axis=0)
            a.plot(t, np.clip(nees, CLIP[0], CLIP[1]), lw=1, label=name)
            nis = np.clip(np.nanmean(np.stack([s["nis"][:n] for s in runs]), axis=0), CLIP[0], CLIP[1])
        if np.isfinite(nis).any():
            b.plot(t, nis, lw=1, label=name)
    M = len(next(iter(have.values())))
    lo, hi = chi2_band(3, M)
    a.axhspan(lo, hi, color="k", alpha=0.12, label=f"95 % band, {M} runs")
    dof = next(iter(have.values()))[0]["nis_dof"]
    d = float(np.median(dof[dof > 0])) if (dof > 0).any() else 0
    if d:
        lo, hi = chi2_band(d, M)
        b.axhspan(lo, hi, color="k", alpha=0.12, label=f"95 % band (dof {d:g})")
    a.set(xlabel="t (s)", ylabel="average NEES (position, d = 3)", yscale="log",
          title=f"{title}: NEES (clipped to [{CLIP[0]:g}, {CLIP[1]:g}])")
    b.set(xlabel="t (s)", ylabel="average NIS", title="NIS (Kalman family)", yscale="log")
    a.legend(fontsize=8)
    b.legend(fontsize=8)
    return _png(fig, path)


class _quiet:
    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


def _f(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


TABLE = ["dataset", "task", "label", "runs", "diverged", "lost", "failed", "pos_rmse", "pos_rmse_ci95",
         "pos_rmse_median", "ate",
         "final_err", "drift_pct", "anees", "anees_inside", "anis", "us_per_step"]


def _table(rows, cols) -> str:
    cols = [c for c in cols if any(c in r for r in rows)]
    out = ["<table><tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in cols) + "</tr>"]
    for r in rows:
        cells = []
        for c in cols:
            v = r.get(c, "")
            if c in ("anees", "anis") and r.get(f"{c}_flag") == "collapsed":
                v = "collapsed"
            elif c == "lost":
                v = summary.lost_cell(r)
            elif isinstance(v, float):
                v = "nan" if not np.isfinite(v) else f"{v:.4g}"
            cells.append(f"<td>{html.escape(str(v))}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    return "\n".join(out + ["</table>"])


def make_report(d: Path, out: Path | None = None) -> Path:
    """Write the PNGs and ``report.html`` for result directory ``d``; returns the HTML path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = Path(d)
    if (d / "units").is_dir():
        groups, rows = _load_campaign(d)
    elif (d / "estimates").is_dir():
        groups, rows = _load_eval(d)
    else:
        raise ReplayError(f"{d}: not a result directory (no units/ from `replay campaign run`, "
                          "no estimates/ from `replay eval`)")
    if not groups:
        raise ReplayError(f"{d}: no finished runs to report")
    out = Path(out) if out else d / "report"
    out.mkdir(parents=True, exist_ok=True)
    parts = [f"<h1>replay report: {html.escape(str(d))}</h1>",
             "<h2>Leaderboard</h2>", _table(rows, TABLE)]
    paired = d / "paired.csv"
    if paired.is_file():
        with open(paired, newline="") as fh:
            prow = list(csv.DictReader(fh))
        if prow:
            parts += ["<h2>Paired comparisons (common random numbers: mean of a - b, 95 % interval)</h2>",
                      _table(prow, list(prow[0]))]
    for i, ((dataset, task), filters) in enumerate(sorted(groups.items())):
        title = f"{dataset} / {task}"
        grows = [r for r in rows if r.get("dataset") == dataset and r.get("task") == task]
        pngs = [_trajectory(plt, title, filters, out / f"trajectory_{i}.png"),
                _error(plt, title, filters, out / f"error_{i}.png"),
                _rmse(plt, title, grows, out / f"rmse_{i}.png"),
                _consistency(plt, title, filters, out / f"consistency_{i}.png")]
        parts.append(f"<h2>{html.escape(title)}</h2>")
        for p in pngs:
            if p is not None:
                b64 = base64.b64encode(p.read_bytes()).decode()
                parts.append(f'<p><img alt="{p.stem}" src="data:image/png;base64,{b64}"></p>')
    style = ("body{font-family:sans-serif;margin:2em}table{border-collapse:collapse;font-size:12px}"
             "td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}img{max-width:100%}")
    page = (f"<!doctype html><html><head><meta charset='utf-8'><title>replay report</title>"
            f"<style>{style}</style></head><body>\n" + "\n".join(parts) + "\n</body></html>\n")
    path = out / "report.html"
    path.write_text(page, encoding="utf-8")
    return path
