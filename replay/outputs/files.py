"""Outputs of an evaluation: the printed table, leaderboard CSV, estimates, manifest.

Leaderboard columns (stable; one row per dataset x task x filter):

``dataset, task, filter, runs, diverged, seed, first`` — the configuration;
``pos_rmse, pos_rmse_ci95`` — mean over runs of the per-run 3-D position RMSE
(m) and the half-width of its 95 % interval; ``x_rmse``, ``y_rmse``, ``z_rmse``
(and their ``_ci95``) the same per axis; ``<angle>_rmse`` (rad, wrapped) where
the task scores angles; ``us_per_step`` — median filter time per step in
microseconds; ``scored, masked`` — reference samples scored and skipped;
``version, config_hash`` — package version and the hash of the configuration;
``pos_rmse_vs_<baseline>, pos_rmse_vs_<baseline>_ci95`` — paired comparison
with the baseline filter (the first listed unless chosen): mean over runs of
this filter's per-run position RMSE minus the baseline's in the same run
(common random numbers, :func:`replay.metrics.paired`; runs where either
diverged are skipped) and the half-width of its 95 % interval; empty in the
baseline's own row.
"""
from __future__ import annotations

import csv
import gzip
import json
import os
from pathlib import Path

import numpy as np

from replay.evaluate import Evaluation, manifest
from replay.score import rmse_over_time

FIXED = ["dataset", "task", "filter", "runs", "diverged", "seed", "first"]
TAIL = ["us_per_step", "scored", "masked", "version", "config_hash"]


def paired_columns(ev: Evaluation, baseline: str | None = None, metric: str = "pos_rmse") -> dict:
    """{filter: {"<metric>_vs_<baseline>": diff, "..._ci95": half-width}} (empty strings for the baseline)."""
    from replay.util.errors import ReplayError
    from replay.metrics import paired

    names = [r.name for r in ev.results]
    base = baseline or names[0]
    if base not in names:
        raise ReplayError(f"--baseline {base!r}: not among the filters run ({', '.join(names)})")

    def per_run(r):
        return [np.nan if m["diverged"] else m.get(metric, np.nan) for m in r.runs]

    ref = per_run(ev.results[names.index(base)])
    col = f"{metric}_vs_{base}"
    out = {}
    for r in ev.results:
        if r.name == base:
            out[r.name] = {col: "", f"{col}_ci95": ""}
        else:
            p = paired(per_run(r), ref)
            out[r.name] = {col: p["diff"], f"{col}_ci95": p["diff_ci95"]}
    return out


def leaderboard_rows(ev: Evaluation, baseline: str | None = None) -> list[dict]:
    rows = []
    pairs = paired_columns(ev, baseline) if len(ev.results) > 1 else {}
    for r in ev.results:
        s = r.summary
        row = {"dataset": ev.config["dataset"], "task": ev.config["task"], "filter": r.name,
               "runs": s["runs"], "diverged": s["diverged"], "seed": ev.config["seed"],
               "first": ev.config["first"] or ""}
        row.update({k: v for k, v in s.items() if k.endswith(("_rmse", "_rmse_ci95"))})
        row.update(pairs.get(r.name, {}))
        row.update(us_per_step=s["us_per_step"], scored=s["scored"], masked=s["masked"],
                   version=ev.config["replay_version"], config_hash=ev.config["config_hash"])
        rows.append(row)
    return rows


def _columns(rows):
    metric = []
    for row in rows:
        metric += [k for k in row if k not in FIXED + TAIL and k not in metric]
    return FIXED + metric + TAIL


def _fmt(v):
    if isinstance(v, float):
        return "nan" if not np.isfinite(v) else f"{v:.6g}"
    return str(v)


def format_table(ev: Evaluation) -> str:
    """The table ``replay eval`` prints."""
    rows = leaderboard_rows(ev)
    metrics = [k for k in _columns(rows) if k.endswith("_rmse")]
    head = ["filter"] + metrics + ["us/step", "diverged"]
    body = []
    for row in rows:
        cells = [row["filter"]]
        for k in metrics:
            v, c = row.get(k, np.nan), row.get(f"{k}_ci95", np.nan)
            cells.append(f"{v:.4f}" + (f" ±{c:.4f}" if np.isfinite(c) else ""))
        cells += [f"{row['us_per_step']:.1f}", f"{row['diverged']}/{row['runs']}"]
        body.append(cells)
    widths = [max(len(str(x)) for x in col) for col in zip(head, *body)]
    line = lambda cells: "  ".join(str(c).rjust(w) if i else str(c).ljust(w)
                                   for i, (c, w) in enumerate(zip(cells, widths)))
    cfg = ev.config
    title = (f"{cfg['dataset']}  task={cfg['task']}  runs={cfg['runs']}  seed={cfg['seed']}"
             + (f"  first={cfg['first']}" if cfg["first"] else ""))
    note = "RMSE: mean over runs of per-run RMSE (m, rad), ± half-width of the 95 % interval"
    return "\n".join([title, line(head), *(line(b) for b in body), note])


def write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_leaderboard(rows: list[dict], path: Path) -> None:
    from io import StringIO

    buf = StringIO()
    w = csv.DictWriter(buf, fieldnames=_columns(rows), extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: _fmt(v) for k, v in row.items()})
    write_atomic(path, buf.getvalue())


def write_estimates(ev: Evaluation, out: Path) -> None:
    """Per filter: ``estimates/<filter>.csv.gz`` (every run, every step) and the RMSE-over-time curve."""
    est_dir = out / "estimates"
    est_dir.mkdir(parents=True, exist_ok=True)
    for r in ev.results:
        nx = r.estimates[0].x.shape[1]
        head = ["run", "k", "t"] + [f"x{i}" for i in range(nx)] + [f"P{i}{i}" for i in range(nx)]
        head += [f"err_{axis}" for axis in ev.axis_names]
        with gzip.open(est_dir / f"{r.name}.csv.gz", "wt", newline="") as fh:
            fh.write(",".join(head) + "\n")
            for run, (est, err) in enumerate(zip(r.estimates, r.errors)):
                n = len(est.x)
                block = np.column_stack([np.full(n, run), np.arange(n), ev.t[:n], est.x,
                                         np.diagonal(est.P, axis1=1, axis2=2), err["position"]])
                np.savetxt(fh, block, delimiter=",", fmt="%.10g")
        curve = rmse_over_time([e["position"] for e in r.errors])
        np.savetxt(est_dir / f"{r.name}_rmse_over_time.csv", np.column_stack([ev.t, curve]),
                   delimiter=",", header="t,pos_rmse_across_runs", comments="", fmt="%.10g")


def write_all(ev: Evaluation, out: Path, baseline: str | None = None) -> dict:
    """Leaderboard, estimates and manifest into ``out``; returns the paths written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_leaderboard(leaderboard_rows(ev, baseline), out / "leaderboard.csv")
    write_estimates(ev, out)
    write_atomic(out / "manifest.json", json.dumps(manifest(ev), indent=2, default=str))
    return {"leaderboard": out / "leaderboard.csv", "manifest": out / "manifest.json",
            "estimates": out / "estimates"}
