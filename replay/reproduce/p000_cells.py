"""Paper 000's sweep cells and the one computation of a cell (through ``replay eval``'s pipeline).

A **cell** is one configuration of the synthetic lake trial and of the filters' model:

* ``noise``: the sensors' noise level. ``None`` = ``sim/lake-depth`` as generated (RMS
  over the run 0.119 m, 0.119 m/s, 0.0207 rad: ρ = 0.59, 0.024, 0.041 of the fixed R's
  std); a number ρ puts every sensor's RMS at ρ × the fixed R's std (the generator's
  ``noise_rms`` = ρ · (0.2 m, 5 m/s, 0.5 rad)), the regimes and drift varying around it;
* ``kappa``: the filters' process noise Q = κ · diag(0.2², 1², 0.5²) (the digest's fallback
  for the printed Q, read in SI units; κ = 1 is the paper's);
* ``profile``: ``None`` = the fixed maneuvering schedule, an integer = the random schedule
  of that ``profile_seed`` (:func:`replay.sim.lake_depth.random_profile`).

Every cell runs with the same master seed, so cells differ only by what they sweep
(the same noise draws, scaled: common random numbers across cells as well as across
filters). :func:`compute` runs one cell's filters with :func:`replay.run.evaluation.evaluate`
(the pipeline of ``replay eval``) and keeps, per filter, the leaderboard row and the
per-run RMSE of each channel; the maneuver / level split scores each run again with
the pipeline's scorer (:func:`replay.scoring.scorer.score_run`) on the same estimates, the
reference restricted to the maneuver segments (``frame.meta["maneuvers"]``) or to the
rest.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from replay.scoring import metrics, scorer
from replay.run.evaluation import command_line, evaluate
from replay.models.depth import R_FIXED, paper_Q
from replay.run.pipeline import plain
from replay.sim.lake_depth import base_for_rms, make_frame

DATASET, TASK = "sim/lake-depth", "depth"
R_STD = np.sqrt(np.diag(R_FIXED))
Q_DIAG = np.diag(paper_Q()[0])
CHANNELS = (("depth", "m"), ("speed", "m/s"), ("pitch", "rad"))
MAIN = {  # label -> (filter, parameters): the paper's three and the baselines, same particle count
    "GPF": ("gpf", {}),
    "MMPF": ("mmpf", {}),
    "EKF": ("ekf", {}),
    "UKF": ("ukf", {}),
    "PF": ("pf", {"n_particles": 1000}),
}
ABLATIONS = {  # GPF with one part changed (same filter stream as GPF: common random numbers)
    "GPF without grey particles": ("gpf", {"grey": False}),
    "GPF with the fixed R": ("gpf", {"wavelet": False}),
    "GPF, GM(1,1) eq. 12 derived": ("gpf", {"grey_response": "continuous"}),
    "GPF, GM(1,1) eq. 12 as printed": ("gpf", {"grey_response": "printed"}),
}
VARIANTS = {**MAIN, **ABLATIONS}
# sim/lake-depth's default sensors: their RMS over a 90 s run (base_sigma times the regimes' RMS factor)
GENERATED_RMS = tuple(float(b) / f for b, f in zip(next(p.default for p in make_frame.PARAMS if p.name == "base_sigma"),
                                                   base_for_rms((1.0, 1.0, 1.0))))


def tidy(x: float) -> float:
    """A float as a short decimal (for commands and manifests: 0.006, not 0.006000000000000001)."""
    return float(f"{float(x):.10g}")


@dataclass(frozen=True)
class Cell:
    noise: float | None  # rho (sensor RMS / fixed R's std); None: as generated
    kappa: float  # Q = kappa * the paper's Q
    profile: int | None = None  # profile_seed; None: the fixed schedule

    def dataset_params(self, duration: float | None = None) -> dict:
        p = {}
        if self.noise is not None:
            p["noise_rms"] = [tidy(self.noise * s) for s in R_STD]
        if self.profile is not None:
            p["profile_seed"] = int(self.profile)
        if duration is not None:
            p["duration"] = float(duration)
        return p

    def task_params(self) -> dict:
        return {} if self.kappa == 1.0 else {"Q": [tidy(self.kappa * q) for q in Q_DIAG]}

    @property
    def noise_text(self) -> str:
        return "as generated" if self.noise is None else f"{self.noise:g} R"

    @property
    def name(self) -> str:
        prof = "fixed profile" if self.profile is None else f"profile {self.profile}"
        return f"sensors {self.noise_text}, κ = {self.kappa:g}, {prof}"


def command(config: dict) -> str:
    """The ``replay eval`` command of an evaluation (task parameters that differ from their
    defaults included by :func:`replay.run.evaluation.command_line`)."""
    return command_line(config)


def _segment_scores(records, mask_of) -> dict:
    """Per-run channel RMSE of ``records`` with the reference restricted to ``mask_of(problem)``."""
    out = {ch: [] for ch, _ in CHANNELS}
    for rec in records:
        p, est = rec["problem"], rec["estimates"]
        m = scorer.score_run(dataclasses.replace(p, truth_valid=p.truth_valid & mask_of(p)), est)
        for ch, _ in CHANNELS:
            out[ch].append(np.nan if rec["metrics"]["diverged"] else m[f"{ch}_rmse"])
    return {ch: np.asarray(v, float) for ch, v in out.items()}


def maneuver_mask(problem) -> np.ndarray:
    t = np.asarray(problem.t, float)
    man = np.zeros(len(t), bool)
    for a, b, _ in problem.frame_meta["maneuvers"]:
        man |= (t >= a) & (t < b)
    return man


def compute(job) -> dict:
    """One cell: ``(cell, labels, runs, seed, duration, curves)`` -> per-label results (module docstring).

    The labels' filters must differ (one ``evaluate`` call: ``filter_params`` by filter name)."""
    cell, labels, runs, seed, duration, want_curves = job
    names = [VARIANTS[lab][0] for lab in labels]
    ev = evaluate(DATASET, task=TASK, filters=names, runs=runs, seed=seed,
                  dataset_params=cell.dataset_params(duration), task_params=cell.task_params(),
                  filter_params={VARIANTS[lab][0]: VARIANTS[lab][1] for lab in labels})
    out = {"cell": cell, "labels": list(labels), "command": command(ev.config), "t": np.asarray(ev.t, float),
           "maneuvers": plain(ev.frame_meta["maneuvers"]), "filters": {}}
    for lab, res, row in zip(labels, ev.results, ev.rows):
        div = np.array([bool(m["diverged"]) for m in res.runs])
        per = {ch: np.where(div, np.nan, [m.get(f"{ch}_rmse", np.nan) for m in res.runs]) for ch, _ in CHANNELS}
        f = {"row": plain(row), "rmse": per, "lost": [m.get("lost") for m in res.runs],
             "man": _segment_scores(res.records, maneuver_mask),
             "level": _segment_scores(res.records, lambda p: ~maneuver_mask(p))}
        if want_curves:
            f["curves"] = {"depth": scorer.rmse_over_time([e["position"] for e in res.errors]),
                           "speed": scorer.rmse_over_time([e["speed"] for e in res.errors]),
                           "pitch": scorer.rmse_over_time([e["pitch"] for e in res.errors])}
        out["filters"][lab] = f
    return out


# ---------------------------------------------------------------- comparisons

def paired(a, b) -> tuple[float, float]:
    """Mean of the per-run differences a - b and its 95 % half-width (:func:`replay.scoring.metrics.paired`)."""
    p = metrics.paired(a, b)
    return p["diff"], p["diff_ci95"]


def status(diffs) -> str:
    """``holds`` when every paired interval lies below 0, ``fails`` when one lies above 0, else
    ``unresolved``. ``diffs``: [(mean, half-width), ...] of "smaller minus larger" claims."""
    if all(np.isfinite(m) and np.isfinite(c) and m + c < 0 for m, c in diffs):
        return "holds"
    if any(np.isfinite(m) and np.isfinite(c) and m - c > 0 for m, c in diffs):
        return "fails"
    return "unresolved"


def fmt(m: float, c: float | None = None, sign: bool = False) -> str:
    """``m ± c`` with two significant digits on the half-width (3 on ``m`` without one)."""
    if not np.isfinite(m):
        return "n/a"
    if c is None or not np.isfinite(c) or c <= 0:
        return f"{m:+.3g}" if sign else f"{m:.3g}"
    d = max(0, 1 - int(np.floor(np.log10(c))))
    return f"{m:+.{d}f} ± {c:.{d}f}" if sign else f"{m:.{d}f} ± {c:.{d}f}"
