"""The gap to the offline optimum: each row against the best smoother row on the same measurements.

Replay is offline, so a smoother (a row whose filter class declares ``OFFLINE = True``: the
RTS rows ``kf+rts``, ``ekf+rts``, ``ukf+rts``, ``ckf+rts``, :mod:`replay.filters.smoothers`, and
``pf+ffbsi``, :mod:`replay.filters.ffbsi`)
uses every measurement of a run, after each step too: on the same model and inputs it bounds
what a causal filter reaches. Where such a row ran in a group of configurations on the same
measurements (:func:`replay.scoring.summary.group_key`), the best of them (lowest mean
``pos_rmse`` over runs that did not diverge) is the reference of every other row of the group:

``gap_to`` — the label of that smoother;
``gap_m, gap_m_ci95`` — mean over the common runs of this row's ``pos_rmse``
minus the smoother's in the same run, and the half-width of its 95 % Student-t interval
(:func:`replay.scoring.metrics.paired`, the paired columns' statistics): how much is left to gain;
``gap_ratio, gap_ratio_ci95`` — mean over the common runs of the per-run ratio of the two
``pos_rmse`` and its 95 % half-width (:func:`replay.scoring.significance.t_interval`).

In the best smoother's own row ``gap_to`` is its own label (gap 0, ratio 1); empty in groups
without a smoother. The intervals are NaN with one common run (a recording). A row below the
smoother (a negative gap) is possible: another model or other inputs, a smoother of a poorer
model, or chance over few runs; the sign is printed as it is.
"""

from __future__ import annotations

import math

import numpy as np

from replay.scoring import metrics
from replay.filters import FILTERS
from replay.scoring.summary import group_key, per_run

COLUMNS = ("gap_to", "gap_m", "gap_m_ci95", "gap_ratio", "gap_ratio_ci95")


def offline(name: str) -> bool:
    """Whether the built-in filter ``name`` is a smoother (its class's ``OFFLINE``); plugins,
    recorded estimates and names that do not load: False (nothing is imported for them)."""
    if not isinstance(name, str) or name not in FILTERS.builtin:
        return False
    try:
        return bool(getattr(FILTERS.load(name), "OFFLINE", False))
    except Exception:  # noqa: BLE001 — a row whose filter cannot load is not a smoother
        return False


def _mean(row) -> float:
    try:
        v = float(row.get("pos_rmse"))
    except (TypeError, ValueError):
        return math.nan
    return v if row.get("runs") else math.nan


def add_gap(rows: list[dict], configs: dict, records: dict) -> list[dict]:
    """Add the :data:`COLUMNS` to ``rows`` (in place; module docstring); ``configs``: config hash
    -> configuration, ``records``: config hash -> its run records."""
    # lazy: start-up, scipy.stats (measured ~2 s to import) only where a smoother row ran
    from replay.scoring.significance import t_interval  # noqa: PLC0415

    groups = {}
    for row in rows:
        groups.setdefault(group_key(configs[row["config_hash"]]), []).append(row)
    for members in groups.values():
        smoothers = [r for r in members if offline(r["filter"]) and math.isfinite(_mean(r))]
        if not smoothers:
            continue
        best = min(smoothers, key=_mean)
        ref = per_run(records[best["config_hash"]], "pos_rmse")
        for row in members:
            if row is best:
                row.update(gap_to=row["label"], gap_m=0.0, gap_ratio=1.0)
                row.update(gap_m_ci95="", gap_ratio_ci95="")
                continue
            mine = per_run(records[row["config_hash"]], "pos_rmse")
            common = [r for r in sorted(set(ref) & set(mine)) if np.isfinite(mine[r]) and np.isfinite(ref[r])]
            a, b = np.array([mine[r] for r in common], float), np.array([ref[r] for r in common], float)
            p = metrics.paired(a, b)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio, ratio_ci = t_interval(a / b) if len(common) else (math.nan, math.nan)
            row.update(
                gap_to=best["label"],
                gap_m=p["diff"],
                gap_m_ci95=p["diff_ci95"],
                gap_ratio=float(ratio),
                gap_ratio_ci95=float(ratio_ci),
            )
    return rows


def cell(row) -> str:
    """The printed gap: ``+0.123 ±0.010 m (×1.25 ±0.03)``; ``–`` without one, ``(best)`` in the
    smoother's own row."""
    if row.get("gap_to") in ("", None) or _num(row.get("gap_m")) is None:
        return "–"
    if row.get("gap_to") == row.get("label"):
        return "(best smoother)"
    d, dc = _num(row.get("gap_m")), _num(row.get("gap_m_ci95"))
    r, rc = _num(row.get("gap_ratio")), _num(row.get("gap_ratio_ci95"))
    text = f"{d:+.3g}" + (f" ±{dc:.2g}" if dc is not None else "") + " m"
    if r is not None:
        text += f" (×{r:.3g}" + (f" ±{rc:.2g}" if rc is not None else "") + ")"
    return text


def _num(v):
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def lines(rows) -> list[str]:
    """The lines ``replay eval`` prints under its table: each row's gap to the best smoother."""
    out = []
    for best in (r for r in rows if r.get("gap_to") and r.get("gap_to") == r.get("label")):
        group = [r for r in rows if r.get("gap_to") == best["label"] and r is not best]
        out += [
            f"gap to the best smoother ({best['label']}): this row's pos_rmse minus its, paired over runs "
            "(± 95 % half-width), and their ratio"
        ] + [f"  {r['label']}: {cell(r)}" for r in group]
    return out
