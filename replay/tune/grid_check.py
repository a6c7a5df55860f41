"""The optimiser's distance from a grid optimum, where a grid is cheap (issue 35 item 4;
``replay eval --tune N --tune-grid G``).

For each filter whose searched parameters are all numeric, the G points per parameter (log-spaced on a
``log`` range, evenly on a float one, rounded and deduplicated on an integer one) make a grid of at most
:data:`MAX_POINTS` configurations, each scored on the first tune's training data with the tune's own
objective and pipeline (:class:`replay.tune.run.Runner`: campaign units in ``OUT/units``). Reported per
filter: the grid's best point and training score, the first tune's tuned training score, their gap
(tuned minus grid: negative when the optimiser found better than the grid) and, per parameter, the
distance of the tuned value from the grid's best in log10 units (``log`` ranges) or as a share of the range,
and of the ratio q_scale/r_scale where both are searched (an RMSE objective fixes only that ratio, the
Kalman gain: along it the values themselves may lie decades apart at the same score).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from replay.util.errors import ReplayError
from replay.campaign import execute
from replay.campaign.lock import locked
from .grid import points
from .run import Runner

MAX_POINTS = 400


def axis(d, g: int) -> list:
    if d.kind == "log":
        return [float(v) for v in np.geomspace(d.low, d.high, g)]
    if d.kind == "int":
        return sorted({int(round(v)) for v in np.linspace(d.low, d.high, g)})
    return [float(v) for v in np.linspace(d.low, d.high, g)]


def distances(t, out, tuned_rows: list[dict], g: int) -> list[dict]:
    """One row per filter (module docstring); ``tuned_rows``: the first tune's board rows."""
    if g < 2:
        raise ReplayError(f"--tune-grid {g}: at least 2 points per parameter")
    out = Path(out)
    rows = []
    with locked(out / "units", who="replay eval --tune-grid"):
        ctx, _ = execute.open_backend(1, None, None, 5.0, 1)
        with ctx as mapper, np.errstate(all="ignore"):
            run = Runner(t, out / "units", mapper)
            for name in t.filters:
                dims = t.dims[name]
                row = next((r for r in tuned_rows if r["filter"] == name and r["label"].endswith("(tuned)")), None)
                if row is None or any(d.kind == "choice" for d in dims):
                    continue
                grid = {d.key: axis(d, g) for d in dims}
                pts = points(grid)
                if len(pts) > MAX_POINTS:
                    raise ReplayError(
                        f"--tune-grid {g}: {len(pts)} points for {name} (at most {MAX_POINTS}: a grid is only "
                        "worth it when cheap)"
                    )
                scores = [run.score(t.configs("train", name, p)) for p in pts]
                best = int(np.argmin(scores))
                tuned = row["_params"]
                dist = {
                    d.key: (
                        abs(math.log10(tuned[d.key] / pts[best][d.key]))
                        if d.kind == "log"
                        else abs(tuned[d.key] - pts[best][d.key]) / (d.high - d.low)
                    )
                    for d in dims
                }
                q, r = f"{name}.q_scale", f"{name}.r_scale"
                if q in dist and r in dist:  # an RMSE objective fixes only the ratio of Q to R (the gain)
                    ratio = math.log10((tuned[q] / tuned[r]) / (pts[best][q] / pts[best][r]))
                    dist["q_scale/r_scale"] = abs(ratio)
                rows.append(
                    dict(
                        filter=name,
                        grid_points=len(pts),
                        grid_best=pts[best],
                        grid_train=float(scores[best]),
                        tuned_train=float(row["train_score"]),
                        gap=float(row["train_score"]) - float(scores[best]),
                        distance=dist,
                    )
                )
    return rows


def format_rows(rows: list[dict]) -> list[str]:
    out = []
    for r in rows:
        where = ", ".join(f"{k.split('.', 1)[1]} {v:.3g}" for k, v in r["grid_best"].items())
        far = ", ".join(f"{k.split('.', 1)[-1]} {v:.2f}" for k, v in r["distance"].items())
        out.append(
            f"{r['filter']}: grid optimum ({r['grid_points']} points) at {where}: train {r['grid_train']:.4g}; "
            f"tune 0 {r['tuned_train']:.4g} (gap {r['gap']:+.3g}); tuned value's distance from it: {far} "
            "(log10 units on a log range, else share of the range)"
        )
    return out
