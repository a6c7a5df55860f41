"""Leaderboard and paired comparisons of a campaign directory; merging result directories.

Leaderboard columns (stable; one row per dataset x task x filter x parameter set):

``dataset, task, filter, label, params, runs, diverged, failed, seed, first`` —
the configuration (``params``: the filter's parameters as JSON, defaults
included; ``label``: the filter name plus the parameters that differ between
rows of the same filter; ``runs``: stored successful runs; ``diverged``: runs
that diverged, left out of every mean; ``failed``: runs that raised);

``<m>, <m>_ci95`` for each per-run metric ``m`` — the mean over non-diverged runs
and the half-width of its 95 % Student-t interval: ``pos_rmse``, ``x_rmse``,
``y_rmse``, ``z_rmse``, ``<angle>_rmse`` (rad), ``ate`` (m, after
``alignment``), ``final_err`` (m), ``drift_pct`` (%), ``nees``, ``nis``
(per-run time means; see :mod:`replay.metrics`);

``anees, anees_lo, anees_hi, anees_inside`` and the same for ``anis`` — the
ensemble consistency (:func:`replay.metrics.consistency`);

``us_per_step, alignment, version, config_hash`` — median filter time per step
(µs; amortised over the batch for batched runs), ATE alignment, package
version, configuration hash (the directory name under ``units/``).

``paired.csv``: ``dataset, task, a, b, metric, n, diff, diff_ci95, a_better``
for every two configurations on the same dataset and task (common random
numbers): mean of a - b over the runs both finished without divergence.
"""
from __future__ import annotations

import csv
import itertools
import json
from pathlib import Path

import numpy as np

from replay import metrics
from replay.util.errors import ReplayError
from replay.score import ci95

from .store import Store

HEAD = ["dataset", "task", "filter", "label", "params", "runs", "diverged", "failed", "seed", "first"]
RUN_METRICS = ["pos_rmse", "x_rmse", "y_rmse", "z_rmse", "ate", "final_err", "drift_pct", "nees", "nis"]
ENSEMBLE = ["anees", "anees_lo", "anees_hi", "anees_inside", "anis", "anis_lo", "anis_hi", "anis_inside"]
TAIL = ["us_per_step", "alignment", "version", "config_hash"]
PAIRED = ["dataset", "task", "a", "b", "metric", "n", "diff", "diff_ci95", "a_better"]


def _mean(vals):
    v = np.asarray(vals, float)
    return float(np.nanmean(v)) if np.isfinite(v).any() else float("nan")


def config_row(store: Store, h: str, cfg: dict) -> dict:
    recs = store.records(h)
    done = [r for r in recs if r["status"] == "done"]
    ok = [r for r in done if not r["metrics"]["diverged"]]
    row = {"dataset": cfg["dataset"], "task": cfg["task"], "filter": cfg["filter"], "label": cfg["filter"],
           "params": json.dumps(cfg["filter_params"], sort_keys=True, separators=(",", ":")),
           "runs": len(done), "diverged": len(done) - len(ok), "failed": len(recs) - len(done),
           "seed": cfg["seed"], "first": cfg["first"] or ""}
    names = list(RUN_METRICS)
    for r in done:
        names += [k for k in r["metrics"] if k.endswith("_rmse") and k not in names]
    for k in names:
        vals = [r["metrics"].get(k, np.nan) for r in ok]
        row[k], row[f"{k}_ci95"] = _mean(vals), ci95(vals)
    row.update(_ensemble(store, h, [r["run"] for r in ok]))
    us = [r["metrics"]["us_per_step"] for r in done if np.isfinite(r["metrics"]["us_per_step"])]
    row.update(us_per_step=float(np.median(us)) if us else float("nan"), alignment=cfg["alignment"],
               version=(recs[0]["version"] if recs else ""), config_hash=h)
    return row


def _ensemble(store, h, runs) -> dict:
    out = {k: float("nan") for k in ENSEMBLE}
    if not runs:
        return out
    cols = [store.series(h, r, ["nees", "nis", "nis_dof"]) for r in runs]
    n = min(len(c["nees"]) for c in cols)
    nees = np.stack([c["nees"][:n] for c in cols])
    out.update(metrics.consistency(nees, 3 if nees.size else 0, "anees"))  # 3-D position NEES
    nis = np.stack([c["nis"][:n] for c in cols])
    dof = cols[0]["nis_dof"][:n]
    out.update(metrics.consistency(nis, dof, "anis"))
    return out


def _labels(rows):
    by_filter = {}
    for row in rows:
        by_filter.setdefault(row["filter"], []).append(json.loads(row["params"]))
    for row in rows:
        group = by_filter[row["filter"]]
        p = json.loads(row["params"])
        vary = [k for k in p if any(g.get(k) != p[k] for g in group)]
        row["label"] = row["filter"] + (f"({', '.join(f'{k}={p[k]}' for k in vary)})" if vary else "")
    return rows


def campaign_rows(out) -> list[dict]:
    """One leaderboard row per stored configuration of the campaign directory ``out``."""
    store = Store(out)
    rows = [config_row(store, h, cfg) for h, cfg in store.configs()]
    rows = [r for r in rows if r["runs"] or r["failed"]]
    return _labels(sorted(rows, key=lambda r: (r["dataset"], r["task"], r["filter"], r["params"])))


def paired_rows(out, rows, metric_names=("pos_rmse", "ate")) -> list[dict]:
    """Paired comparisons of every two configurations on one dataset and task (``rows``: the leaderboard)."""
    store = Store(out)
    groups = {}
    for h, cfg in store.configs():
        key = json.dumps([cfg["dataset"], cfg["dataset_params"], cfg["first"], cfg["task"],
                          cfg["task_params"], cfg["seed"]], sort_keys=True)
        groups.setdefault(key, []).append((h, cfg))
    labels = {r["config_hash"]: r["label"] for r in rows}
    rows = []
    for members in groups.values():
        per = {}
        for h, cfg in members:
            per[h] = {r["run"]: r["metrics"] for r in store.records(h)
                      if r["status"] == "done" and not r["metrics"]["diverged"]}
        for (ha, ca), (hb, _) in itertools.combinations(members, 2):
            common = sorted(set(per[ha]) & set(per[hb]))
            for m in metric_names:
                p = metrics.paired([per[ha][r].get(m, np.nan) for r in common],
                                   [per[hb][r].get(m, np.nan) for r in common])
                rows.append({"dataset": ca["dataset"], "task": ca["task"], "a": labels.get(ha, ha),
                             "b": labels.get(hb, hb), "metric": m, "n": p["n"], "diff": p["diff"],
                             "diff_ci95": p["diff_ci95"], "a_better": p["a_better"]})
    return rows


def columns(rows) -> list[str]:
    extra = []
    for row in rows:
        extra += [k for k in row if k not in HEAD + ENSEMBLE + TAIL and k not in extra]
    return HEAD + extra + ENSEMBLE + TAIL


def _write(rows, path, cols):
    from io import StringIO

    from replay.outputs.files import _fmt, write_atomic

    buf = StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: _fmt(v) for k, v in row.items()})
    write_atomic(path, buf.getvalue())


def summarise(out) -> list[dict]:
    """Write ``leaderboard.csv`` and ``paired.csv`` into the campaign directory; return the rows."""
    out = Path(out)
    with np.errstate(all="ignore"):
        rows = campaign_rows(out)
        _write(rows, out / "leaderboard.csv", columns(rows))
        _write(paired_rows(out, rows), out / "paired.csv", PAIRED)
    return rows


def read_dir(d) -> list[dict]:
    """Leaderboard rows of a result directory: a campaign's units, else its ``leaderboard.csv``."""
    d = Path(d)
    if (d / "units").is_dir():
        with np.errstate(all="ignore"):
            return campaign_rows(d)
    path = d / "leaderboard.csv" if d.is_dir() else d
    if not path.is_file():
        raise ReplayError(f"{d}: no campaign units/ and no leaderboard.csv")
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    for row in rows:
        row.setdefault("label", row.get("filter", ""))
        for k, v in row.items():
            try:
                row[k] = float(v) if k not in HEAD + ["alignment", "version", "config_hash"] else v
            except (TypeError, ValueError):
                pass
    return rows


def merge(dirs, sort: str | None = None) -> list[dict]:
    """Rows of several result directories, one per configuration hash, optionally sorted by a metric."""
    rows, seen = [], set()
    for d in dirs:
        for row in read_dir(d):
            key = (row.get("config_hash"), row.get("filter"), row.get("dataset"), row.get("task"))
            if key in seen:
                continue
            seen.add(key)
            rows.append(row)
    if sort:
        if rows and sort not in rows[0] and not any(sort in r for r in rows):
            known = ", ".join(k for k in columns(rows) if k.endswith(("_rmse", "ate", "err", "pct", "nees", "nis")))
            raise ReplayError(f"--sort {sort}: no such column (e.g. {known})")
        rows.sort(key=lambda r: (not np.isfinite(_num(r.get(sort))), _num(r.get(sort))))
    return rows


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def format_rows(rows) -> str:
    """A compact text table of the main columns."""
    head = ["dataset", "task", "filter", "pos_rmse", "ate", "anees", "diverged", "us/step"]
    body = []
    for r in rows:
        pm, pc = _num(r.get("pos_rmse")), _num(r.get("pos_rmse_ci95"))
        body.append([str(r.get("dataset", "")), str(r.get("task", "")), str(r.get("label") or r.get("filter")),
                     f"{pm:.4f}" + (f" ±{pc:.4f}" if np.isfinite(pc) else ""), f"{_num(r.get('ate')):.4f}",
                     f"{_num(r.get('anees')):.3g}",
                     f"{int(_num(r.get('diverged')) or 0)}/{int(_num(r.get('runs')) or 0)}",
                     f"{_num(r.get('us_per_step')):.1f}"])
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    fmt = lambda cells: "  ".join(c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))
    return "\n".join([fmt(head), *(fmt(b) for b in body)])
