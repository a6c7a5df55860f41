"""Leaderboard rows: one schema for ``replay eval``, campaigns, reproductions and merges.

One row per configuration (dataset x task x filter x parameters x seed), from
its per-run records (:func:`replay.run.pipeline.run_block`), whether they are in
memory (eval) or stored (a campaign directory).

Columns (stable):

``dataset, task, filter, label, params, runs, diverged, lost, lost_share, failed, seed, first`` —
the configuration (``params``: the filter's parameters as JSON, defaults
included; ``label``: the filter name plus the parameters that differ between
rows of the same filter; ``runs``: successful runs; ``diverged``: runs whose
filter diverged (non-finite or non-positive covariance, an exception in its
numeric step, or an error beyond ``divergence_threshold``), left out of every
mean; ``lost``: runs that lost the track by the task's rule (:class:`replay.tasks.Task`),
kept in the means; ``lost_share``: the share of the summed per-run ``pos_rmse``
coming from lost runs (above 0.5 the mean is dominated by lost tracks);
``failed``: runs that could not be computed); ``pos_rmse_median`` beside the mean;

``<m>, <m>_ci95`` for each per-run metric ``m`` — the mean over non-diverged
runs and the half-width of its 95 % Student-t interval: ``pos_rmse``,
``x_rmse``, ``y_rmse``, ``z_rmse`` (m), ``<angle>_rmse`` (rad, wrapped), ``ate``
(m, after ``alignment``), ``final_err`` (m), ``drift_pct`` (%), ``nees``,
``nis`` (per-run time means; see :mod:`replay.scoring.metrics`);

``pos_rmse_vs_<baseline>, pos_rmse_vs_<baseline>_ci95`` — paired comparison
with the baseline configuration of the same dataset and task (the first, or the
one named): mean over runs of this row's per-run ``pos_rmse`` minus the
baseline's in the same run (common random numbers) and its 95 % half-width;
empty in the baseline's own row and where there is one configuration;

``anees, anees_lo, anees_hi, anees_inside, anees_flag`` and the same for ``anis`` — the
ensemble consistency (:func:`replay.scoring.metrics.consistency`); the flag is ``consistent``,
``optimistic``, ``pessimistic`` or ``collapsed`` (then ``anees`` is empty: a collapsed
covariance gives no number worth printing);

``view`` (rows on a view of the dataset only: ``rate=1 window=60:``, :mod:`replay.data.views`);
``content_checked`` (rows on a registered recording only) — whether anything published confirms
the file: its registered checksum, or the rows and time span its upstream listing declares
(:func:`replay.data.checksums.check_loaded`); False flags a file accepted on its structure alone;

``reference`` — where the reference comes from (:mod:`replay.scoring.provenance`: ``simulated truth``,
``onboard solution``, ``fed sensor``, ...; the manifest's ``dataset.reference`` holds the whole record),
``reference_shares`` — the fed inputs that share a source with it (then ``worse_than_measurements`` is
empty: the table states what is compared instead); ``unconstrained`` — the record's lines on an attitude
angle no input measures (:mod:`replay.tasks.fusion_heading`), joined by `` | ``;

``scored, masked`` — reference samples scored and skipped (masked reference),
mean over runs; ``us_per_step`` — median filter time per step (µs; amortised
over the batch); ``alignment, version, config_hash``.
"""

from __future__ import annotations

import json

import numpy as np

from replay.scoring import metrics, scorer
from replay.scoring.record import RunRecord
from replay.util.params import Param
from replay.data.views import NAMES as VIEWS
from replay.tasks import task_class

HEAD = [
    "dataset",
    "task",
    "filter",
    "label",
    "params",
    "runs",
    "diverged",
    "lost",
    "lost_share",
    "failed",
    "seed",
    "first",
]
RUN_METRICS = ["pos_rmse", "x_rmse", "y_rmse", "z_rmse", "ate", "final_err", "drift_pct", "nees", "nis"]
ENSEMBLE = [
    "anees",
    "anees_lo",
    "anees_hi",
    "anees_inside",
    "anees_flag",
    "anis",
    "anis_lo",
    "anis_hi",
    "anis_inside",
    "anis_flag",
]
TAIL = ["measurements", "reference", "scored", "masked", "us_per_step", "alignment", "version", "config_hash"]
# what the filters of a row were given (issue 24): "sensors" (the recording's own), "synthetic"
# (a recording's reference plus the task's noise: a number about the task's noise generator, not
# about the vehicle), "simulated" (a simulated dataset), "recorded" (a recorded estimate: no filter)
SYNTHETIC = "synthetic"
TIMING = ("us_per_step",)


def config_row(cfg: dict, h: str, records: list[RunRecord], series, version: str) -> dict:
    """The row of one configuration from its run records; ``series(run, columns)`` gives a
    run's per-step columns (``nees``, ``nis``, ``nis_dof``)."""
    done = [r for r in records if r.done]
    ok = [r for r in done if not r.diverged]
    row = {
        "dataset": cfg["dataset"],
        "task": cfg["task"],
        "filter": cfg["filter"],
        "label": cfg["filter"],
        "params": json.dumps(cfg["filter_params"], sort_keys=True, separators=(",", ":")),
        "runs": len(done),
        "diverged": len(done) - len(ok),
        "failed": len(records) - len(done),
        "seed": cfg["seed"],
        "first": cfg["first"] or "",
    }
    with np.errstate(all="ignore"):
        agg = scorer.aggregate([r.metrics for r in done], RUN_METRICS)
        row.update(
            {k: v for k, v in agg.items() if k not in ("runs", "diverged", "lost", "us_per_step", "scored", "masked")}
        )
        row["lost"] = agg["lost"] if any(r.metrics.get("lost") is not None for r in ok) or not ok else ""
        row["lost_share"] = lost_share([r.metrics for r in ok])
        dof = ok[0].metrics.get("nees_dof", 3) if ok else 3  # records before nees_dof: 3-D
        row.update(ensemble([series(r.run, ["nees", "nis", "nis_dof"]) for r in ok], nees_dof=dof))
    if len(done) == 1:  # a recorded estimate moved by its align fit: its numbers before the fit, named
        row.update({k: ("" if v is None else v) for k, v in done[0].metrics.items() if k.endswith("_unaligned")})
    row.update(
        measurements=measurements(cfg),
        reference=next((r.reference for r in done if r.reference), ""),  # provenance.py
        scored=agg["scored"],
        masked=agg["masked"],
        us_per_step=agg["us_per_step"],
        alignment=cfg["alignment"],
        version=version,
        config_hash=h,
    )
    if ok and all(r.metrics.get("still") is True for r in ok):  # issue 40: not a filter's error
        row["still"] = True
    shared = next((r.reference_input for r in done if r.reference_input), "")
    if shared:  # the reference is one of the row's inputs: a topic scored against itself
        row["reference_input"] = shared
    if shares := next((r.reference_shares for r in done if r.reference_shares), ""):
        row["reference_shares"] = shares  # the fed inputs that share a source with the reference
    if free := next((r.unconstrained for r in done if r.unconstrained), ""):
        row["unconstrained"] = free  # an attitude angle no input measures: what a distance then means
    checked = [r.content_checked for r in done if r.content_checked is not None]  # recorded files only
    if checked:
        row["content_checked"] = all(checked)
    view = [(k, cfg["dataset_params"][k]) for k in VIEWS if k in (cfg.get("dataset_params") or {})]
    if view:  # a view of the dataset (replay/data/views.py): rows of one dataset at two rates are told apart
        show = lambda v: f"{v:g}" if isinstance(v, float) else ";".join(v) if isinstance(v, list) else str(v)  # noqa: E731
        row["view"] = " ".join(f"{k}={show(v)}" for k, v in view)  # faults: fault=SPEC;SPEC
    return row


def measurements(cfg: dict) -> str:
    """What the filters of configuration ``cfg`` were given (:data:`TAIL`'s ``measurements``)."""
    # lazy: start-up, the dataset registry measured ~40-120 ms on `import replay.trajectory.score_api`
    from replay.data.dataset_ref import simulated  # noqa: PLC0415

    if str(cfg["filter"]).startswith("recorded:"):
        return "recorded"
    if simulated(cfg["dataset"]):
        return "simulated"
    return SYNTHETIC if getattr(task_class(cfg["task"]), "SYNTHETIC", False) else "sensors"


def against_measurements(rows: list[dict], configs: dict, records: dict | None = None) -> list[dict]:
    """With a ``measurements`` row (the raw observations, :mod:`replay.filters.measurements`):
    ``worse_than_measurements`` on every filter row run on the same measurements (:func:`group_key`;
    ``configs``: config hash -> configuration; ``records``: config hash -> its run records) — true
    only when the paired difference of the per-run position RMSE (this row's minus the raw
    observations' in the same run) lies above zero with its 95 % interval, and by more than rounding
    (1e-9 of the RMSE: a 1.3e-13 m difference is the same number), and the reference is independent
    of the measurements (a row with ``reference_shares`` gets ``""``: the table states what is
    compared instead). ``worse_than_measurements_by`` holds the difference and its half-width."""
    key = lambda r: group_key(configs[r["config_hash"]])  # noqa: E731
    meas = {key(r): r for r in rows if r["filter"] == "measurements"}
    for r in rows:
        m = meas.get(key(r))
        if m is None or r is m or str(r["filter"]).startswith("recorded:"):
            continue
        r["worse_than_measurements"] = ""
        if r.get("reference_shares") or m.get("reference_shares") or records is None:
            continue
        mine, ref = per_run(records[r["config_hash"]], "pos_rmse"), per_run(records[m["config_hash"]], "pos_rmse")
        common = sorted(set(mine) & set(ref))
        p = metrics.paired([mine[k] for k in common], [ref[k] for k in common])
        diff, half = p["diff"], p["diff_ci95"]
        scale = max(abs(float(r.get("pos_rmse", 0) or 0)), abs(float(m.get("pos_rmse", 0) or 0)))
        if not (np.isfinite(diff) and np.isfinite(half)):
            continue  # one run: no interval, no judgement
        r["worse_than_measurements"] = bool(diff - half > 1e-9 * scale)
        if r["worse_than_measurements"]:
            r["worse_than_measurements_by"] = f"{diff:.4g} ± {half:.2g}"
    return rows


def lost_share(run_metrics: list[dict]) -> float:
    """The share of the summed per-run ``pos_rmse`` that comes from lost runs: above 0.5, the
    mean is dominated by lost tracks (the printed tables mark such rows)."""
    vals = [(m.get("pos_rmse", np.nan), bool(m.get("lost"))) for m in run_metrics]
    vals = [(v, lost) for v, lost in vals if np.isfinite(v)]
    total = sum(v for v, _ in vals)
    return float(sum(v for v, lost in vals if lost) / total) if total > 0 else float("nan")


def lost_cell(row) -> str:
    """``lost k/N`` (``?`` when the task judged no run), ``*`` when lost runs dominate the mean."""
    lost, runs = row.get("lost", ""), row.get("runs", "")
    share = row.get("lost_share", float("nan"))
    try:
        mark = "*" if float(share) > 0.5 else ""
    except (TypeError, ValueError):
        mark = ""
    return f"{'?' if lost in ('', None) else int(float(lost))}/{int(float(runs))}{mark}"


MIN_SCORED_SHARE = Param(
    "min_scored_share",
    float,
    0.5,
    "a row scored on a smaller share of the reference samples "
    "(scored / (scored + masked)) is flagged in the printed table: its numbers describe only the samples scored",
    low=0.0,
    high=1.0,
)


def scored_share(row) -> float:
    """``scored / (scored + masked)``: the share of the reference samples the row was scored on (NaN if none)."""
    try:
        scored, masked = float(row.get("scored")), float(row.get("masked"))
    except (TypeError, ValueError):
        return float("nan")
    return scored / (scored + masked) if scored + masked > 0 else float("nan")


def scored_cell(row, minimum: float) -> str:
    """The printed share scored, ``!`` when under ``minimum`` (e.g. ``0.4%!``)."""
    share = scored_share(row)
    if share != share:
        return "?"
    text = (
        "100%"
        if share == 1
        else f"{min(100 * share, 99.9):.1f}%"
        if share >= 0.001  # never 100.0% when not all
        else f"{100 * share:.2g}%"
    )
    return text + ("!" if share < minimum else "")


def consistency_cell(row, prefix: str = "anees") -> str:
    """The printed ANEES/ANIS: the number, or ``collapsed`` when the covariance collapsed."""
    if row.get(f"{prefix}_flag") == "collapsed":
        return "collapsed"
    try:
        return f"{float(row.get(prefix)):.3g}"
    except (TypeError, ValueError):
        return "nan"


def ensemble(cols: list[dict], nees_dof: int = 3) -> dict:
    """ANEES (position NEES with ``nees_dof`` degrees of freedom: the task's position axes) and
    ANIS over the runs' per-step ``nees``, ``nis``, ``nis_dof``."""
    out = {k: "" if k.endswith("_flag") else float("nan") for k in ENSEMBLE}
    if not cols:
        return out
    n = min(len(c["nees"]) for c in cols)
    nees = np.stack([c["nees"][:n] for c in cols])
    out.update(metrics.consistency(nees, nees_dof if nees.size else 0, "anees"))
    nis = np.stack([c["nis"][:n] for c in cols])
    out.update(metrics.consistency(nis, cols[0]["nis_dof"][:n], "anis"))
    return out


def label(rows: list[dict]) -> list[dict]:
    """Each row's label: its filter, plus the parameters that differ between rows of that filter."""
    by_filter = {}
    for row in rows:
        by_filter.setdefault(row["filter"], []).append(json.loads(row["params"]))
    for row in rows:
        group = by_filter[row["filter"]]
        p = json.loads(row["params"])
        vary = [k for k in p if any(g.get(k) != p[k] for g in group)]
        row["label"] = row["filter"] + (f"({', '.join(f'{k}={p[k]}' for k in vary)})" if vary else "")
    return rows


def group_key(cfg: dict) -> str:
    """Configurations with the same key ran on the same measurements (paired comparisons)."""
    return json.dumps(
        [
            cfg["dataset"],
            cfg["dataset_params"],
            cfg["first"],
            cfg["task"],
            cfg["task_params"],
            cfg["seed"],
            cfg.get("adapter"),
        ],
        sort_keys=True,
        default=str,
    )


def per_run(records: list[RunRecord], metric: str) -> dict:
    """{run: value} of a metric over the runs that finished without diverging."""
    return {r.run: r.metric(metric) for r in records if r.done and not r.diverged}


def add_paired(
    rows: list[dict], configs: dict, records: dict, baseline: str | None = None, metric: str = "pos_rmse"
) -> list[dict]:
    """Add ``<metric>_vs_<baseline>`` columns to ``rows`` (in place): within each group of
    configurations on the same measurements, against ``baseline`` (a label) or the first row."""
    groups = {}
    for row in rows:
        groups.setdefault(group_key(configs[row["config_hash"]]), []).append(row)
    for members in groups.values():
        if len(members) < 2:
            continue
        base = next((r for r in members if r["label"] == baseline), members[0])
        col = f"{metric}_vs_{base['label']}"
        ref = per_run(records[base["config_hash"]], metric)
        for row in members:
            if row is base:
                row[col], row[f"{col}_ci95"] = "", ""
                continue
            mine = per_run(records[row["config_hash"]], metric)
            common = sorted(set(ref) & set(mine))
            p = metrics.paired([mine[r] for r in common], [ref[r] for r in common])
            row[col], row[f"{col}_ci95"] = p["diff"], p["diff_ci95"]
    return rows


def paired_rows(rows, configs: dict, records: dict, metric_names=("pos_rmse", "ate")) -> list[dict]:
    """Every two configurations on the same measurements, compared run by run (``paired.csv``)."""
    groups = {}
    for row in rows:
        groups.setdefault(group_key(configs[row["config_hash"]]), []).append(row)
    out = []
    for members in groups.values():
        for i, a in enumerate(members):
            for b in members[i + 1 :]:
                for m in metric_names:
                    pa, pb = per_run(records[a["config_hash"]], m), per_run(records[b["config_hash"]], m)
                    common = sorted(set(pa) & set(pb))
                    p = metrics.paired([pa[r] for r in common], [pb[r] for r in common])
                    out.append(
                        {
                            "dataset": a["dataset"],
                            "task": a["task"],
                            "a": a["label"],
                            "b": b["label"],
                            "metric": m,
                            "n": p["n"],
                            "diff": p["diff"],
                            "diff_ci95": p["diff_ci95"],
                            "a_better": p["a_better"],
                        }
                    )
    return out


def columns(rows) -> list[str]:
    """The leaderboard's columns: the fixed head, every metric present, the ensemble and the tail."""
    extra = []
    for row in rows:
        extra += [k for k in row if k not in HEAD + ENSEMBLE + TAIL and k not in extra]
    return HEAD + extra + ENSEMBLE + TAIL
