"""Repeated tunes: intervals that include tuning (issue 35 items 3 and 4; ``replay eval --tune N``).

One tune (:func:`replay.tune.run.tune`) finds one optimum; another sampler seed finds another, and
the gap between two filters' tuned scores can be no more than that. Here the same tune is run
``repeats`` times (default :data:`REPEATS`), tune k with every seed moved by ``1000 k`` (its TPE sampler's, its
runs', a seed split's two), each in ``OUT/tune-k`` with every unit in one store ``OUT/units``.

For a filter and a row (``default`` or ``tuned``), ``X[k, r]`` is the held-out per-run position RMSE of
run r of tune k (over several test sequences, their runs side by side). Its mean is the row's score; its
95 % interval is the Student-t interval of the K per-tune means (K - 1 degrees of freedom): each of
them carries its runs' noise and its tune's optimum, so the interval covers both (over tunes × runs).
Two filters are compared on ``D[k, r] = X_a[k, r] - X_b[k, r]`` (runs paired by their seed, tunes by
their index: independent tunes, so the K per-tune mean differences are independent) with the same
interval; they are called different only when it excludes zero.

The default search space (:func:`default_space`): every filter's declared noise scales ``q_scale`` and
``r_scale`` (the task's Q and R, every sensor's noise, scaled) on log[1e-3, 1e3], and the particle
count of a particle filter on [100, 2000].
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from replay.campaign.store import Store
from replay.run.pipeline import config_hash
from replay.scoring.record import FAILED
from replay.scoring.significance import t_interval
from replay.filters import make_filter
from replay.util.errors import ReplayError
from .run import tune

REPEATS = 3  # tunes per filter, each with its own sampler seed
STRIDE = 1000  # tune k's seeds: the given ones + STRIDE * k
SCALES = "log[1e-3, 1e3]"
PARTICLES = "[100, 2000]"


def default_space(filters) -> list[tuple[str, str, str]]:
    """The search-space entries (:func:`replay.tune.space.entries_from_cli`'s form) of the module docstring."""
    out = []
    for f in filters:
        out += [(f"{f}.q_scale", SCALES, "--tune"), (f"{f}.r_scale", SCALES, "--tune")]
        if "n_particles" in make_filter(f).params():
            out.append((f"{f}.n_particles", PARTICLES, "--tune"))
    return out


def run_repeats(t, out, repeats: int = REPEATS, *, quiet: bool = False, **backend) -> dict:
    """Tune ``t`` (a checked :class:`replay.tune.run.Tune`) ``repeats`` times; returns
    ``{"rows": per filter and kind, "pairs": every tuned pair, "tunes": [each tune's result]}``."""
    if not isinstance(repeats, int) or isinstance(repeats, bool) or repeats < 2:
        raise ReplayError(f"--tune-repeats {repeats}: at least 2 tunes (an interval over tunes needs two)")
    out = Path(out)
    (out / "units").mkdir(parents=True, exist_ok=True)
    tunes = [
        tune(shifted(t, k), out / f"tune-{k}", quiet=quiet, store_dir=out / "units", **backend) for k in range(repeats)
    ]
    store = Store(out / "units")
    X, still = {}, {}  # (filter, kind) -> (K, runs); -> whether a tune's row never moved (summary.marks)
    for k, res in enumerate(tunes):
        for row in res["rows"]:
            kind = "measurements" if row["filter"] == "measurements" else row["label"].split("(")[-1].rstrip(")")
            vals = [
                float(rec.metric("pos_rmse")) if rec.status != FAILED else np.nan
                for c in row["_test"]
                for rec in store.records(config_hash(c.as_dict()))
            ]
            X.setdefault((row["filter"], kind), []).append(vals)
            still[(row["filter"], kind)] = still.get((row["filter"], kind), False) or bool(row.get("still"))
    X = {key: np.array(v, float) for key, v in X.items()}
    rows = [dict(_row(name, kind, x, tunes), still=still[(name, kind)]) for (name, kind), x in X.items()]
    tuned = sorted((n for n, k in X if k == "tuned"), key=lambda n: np.nanmean(X[(n, "tuned")]))
    pairs = [compare(X[(a, "tuned")], X[(b, "tuned")], a, b) for i, a in enumerate(tuned) for b in tuned[i + 1 :]]
    return {"rows": rows, "pairs": pairs, "tunes": tunes, "X": X}


def shifted(t, k: int):
    """Tune ``k`` of ``t``: every seed (the sampler's, the runs', a seed split's) moved by ``STRIDE * k``, so
    that its runs and its sampler are new and its training and test streams stay apart from every other's."""
    sp = t.split
    move = lambda s: None if s is None else s + STRIDE * k  # noqa: E731
    return replace(
        t, seed=t.seed + STRIDE * k, split=replace(sp, train_seed=move(sp.train_seed), test_seed=move(sp.test_seed))
    )


def interval(x) -> tuple[float, float]:
    """Mean of ``x`` (tunes, runs) and the half-width of the 95 % interval of its per-tune means."""
    x = np.asarray(x, float)
    per_tune = np.nanmean(x, axis=1)
    _, half = t_interval(per_tune)
    return float(np.nanmean(per_tune)), half


def compare(xa, xb, a: str, b: str) -> dict:
    """``a`` minus ``b`` over tunes × runs (module docstring): mean, half-width, and whether different."""
    mean, half = interval(np.asarray(xa, float) - np.asarray(xb, float))
    different = bool(np.isfinite(half) and abs(mean) > half)
    return dict(a=a, b=b, difference=mean, ci95=half, different=different)


def _row(name: str, kind: str, x, tunes) -> dict:
    mean, half = interval(x)
    params = []
    for res in tunes:
        row = next((r for r in res["rows"] if r["filter"] == name and kind in r["label"]), None)
        params.append(row["params"] if row and kind == "tuned" else "")
    return dict(
        filter=name,
        kind=kind,
        label={"measurements": "measurements (raw observations)", "default": f"{name} (defaults, not tuned)"}.get(
            kind, f"{name} ({kind})"
        ),
        tunes=x.shape[0],
        runs=x.shape[1],
        pos_rmse=mean,
        ci95=half,
        tune_spread=float(np.nanstd(np.nanmean(x, axis=1), ddof=1)) if x.shape[0] > 1 else float("nan"),
        params=" | ".join(p for p in params if p),
    )


def ranking(res: dict) -> list[str]:
    """One line per tuned filter, best first: its score ± interval, and against the best whether different."""
    tuned = sorted((r for r in res["rows"] if r["kind"] == "tuned"), key=lambda r: r["pos_rmse"])
    if not tuned:
        return []
    best = tuned[0]["filter"]
    lines = [f"best (tuned): {best} {tuned[0]['pos_rmse']:.4g} ± {tuned[0]['ci95']:.2g}"]
    for r in tuned[1:]:
        p = next(p for p in res["pairs"] if p["a"] == best and p["b"] == r["filter"])
        verdict = "different" if p["different"] else "not distinguishable (the interval includes zero)"
        lines.append(f"{best} - {r['filter']}: {p['difference']:+.4g} ± {p['ci95']:.2g}: {verdict}")
    return lines


def format_rows(rows: list[dict]) -> str:
    head = f"{'row':<34}{'tunes':>6}{'runs':>6}{'pos_rmse':>12}{'± 95 %':>10}{'tune spread':>13}"
    lines = [head]
    for r in rows:
        lines.append(
            f"{r['label']:<34}{r['tunes']:>6}{r['runs']:>6}{r['pos_rmse']:>12.4f}{r['ci95']:>10.4f}"
            f"{r['tune_spread']:>13.4f}" + ("  still" if r.get("still") else "")
        )
    lines.append(
        "pos_rmse: held-out position RMSE, mean over tunes x runs; ± 95 %: Student-t interval of the per-tune "
        "means (covers the runs and the tuning); tune spread: standard deviation of the per-tune means; still: the "
        "estimate never moves on the held-out part (its error is the start's, not a filter's)"
    )
    return "\n".join(lines)
