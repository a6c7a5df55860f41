"""What a trial minimises, from the run records of its configuration(s).

* ``mean_rmse`` — mean over runs of the per-run 3-D position RMSE (m), the leaderboard's ``pos_rmse``;
* ``median_rmse`` — its median over runs;
* ``lost`` — the number of runs that lost the track (the task's rule);
* ``nll`` — mean over runs of the innovations' negative log-likelihood (:mod:`replay.scoring.likelihood`:
  ``kf``, ``ekf``, ``ukf``, ``ckf`` on a linear model only);
* ``anees`` — distance of the NEES from consistency, ``|ANEES / d - 1|``, ANEES the mean over
  runs of each run's time-mean position NEES and d its degrees of freedom;
* ``weighted:mean_rmse=1,anees=0.5`` — the weighted sum of those.

A configuration with a failed or diverged run scores ``inf`` (it is not a usable setting). Over
several training datasets the objective is the mean of each dataset's.
"""

from __future__ import annotations

import math

import numpy as np

from replay.scoring.record import RunRecord
from replay.util.errors import ReplayError

BASIC = ("mean_rmse", "median_rmse", "lost", "nll", "anees")


def parse(text: str) -> dict[str, float]:
    """``--objective`` -> {basic objective: weight}."""
    if text in BASIC:
        return {text: 1.0}
    if not text.startswith("weighted:"):
        raise ReplayError(
            f"--objective {text!r}: expected one of {', '.join(BASIC)} or "
            "weighted:NAME=W,NAME=W (e.g. weighted:mean_rmse=1,anees=0.5)"
        )
    out = {}
    for part in text[len("weighted:") :].split(","):
        name, eq, w = part.partition("=")
        name = name.strip()
        if name not in BASIC:
            raise ReplayError(f"--objective {text!r}: unknown objective {name!r} (known: {', '.join(BASIC)})")
        try:
            weight = float(w) if eq else float("nan")
        except ValueError:
            weight = float("nan")
        if not math.isfinite(weight) or weight <= 0:
            raise ReplayError(f"--objective {text!r}: {name} needs a weight > 0 (NAME=W)")
        out[name] = weight
    if not out:
        raise ReplayError(f"--objective {text!r}: no objective named")
    return out


def value(weights: dict[str, float], records: list[RunRecord]) -> float:
    """The objective of one configuration's records."""
    done = [r for r in records if r.done]
    if not records or len(done) < len(records) or any(r.diverged for r in done):
        return math.inf
    return float(sum(w * _basic(name, [r.metrics for r in done]) for name, w in weights.items()))


def why_inf(weights: dict[str, float], records: list[RunRecord]) -> str:
    """Why :func:`value` is infinite for these records (one phrase), or '' when it is finite."""
    done = [r for r in records if r.done]
    if not records:
        return "no run was computed"
    if len(done) < len(records):
        err = next((r.error for r in records if not r.done and r.error), "")
        return f"{len(records) - len(done)} of {len(records)} runs failed" + (f" ({err})" if err else "")
    div = sum(r.diverged for r in done)
    if div:
        return f"{div} of {len(done)} runs diverged (a setting with a diverged run is not usable)"
    bad = [n for n in weights if not math.isfinite(_basic(n, [r.metrics for r in done]))]
    return f"objective {', '.join(bad)} not finite (e.g. no likelihood or NEES)" if bad else ""


def _basic(name: str, ms: list[dict]) -> float:
    if name == "mean_rmse":
        return float(np.mean([m["pos_rmse"] for m in ms]))
    if name == "median_rmse":
        return float(np.median([m["pos_rmse"] for m in ms]))
    if name == "lost":
        return float(sum(bool(m.get("lost")) for m in ms))
    if name == "nll":
        v = [m.get("nll", math.nan) for m in ms]
        return float(np.mean(v)) if all(math.isfinite(x) for x in v) else math.inf
    if name == "anees":
        dof = ms[0].get("nees_dof", 3)
        v = float(np.mean([m["nees"] for m in ms])) / dof
        return abs(v - 1.0) if math.isfinite(v) else math.inf
    raise ReplayError(f"unknown objective {name!r}")
