"""Paper 000's experiments as data: the cells, the filters, and the one computation of a cell.

A :class:`Cell`: the sensors' ``noise`` (None: ``sim/lake-depth`` as generated; ρ: every sensor's
RMS at ρ × the fixed R's std), ``kappa`` (Q = κ · diag(0.2², 1², 0.5²), κ = 1 the paper's) and
``profile`` (None: the fixed schedule; K: ``profile_seed`` K). Cells of one sensor level draw the
same noise, so filters and cells of a level are paired run by run. :func:`compute` runs a cell
through :func:`replay.evaluation.evaluate` and keeps per filter the leaderboard row, the per-run
RMSE of each channel (diverged +inf, lost flags), the same over the maneuvers and the level runs,
and the particle filters' mean ESS / N.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from replay import scorer
from replay.evaluation import command_line, evaluate
from replay.models.depth import R_FIXED, paper_Q
from replay.pipeline import plain
from replay.sim.lake_depth import base_for_rms, make_frame

from .rules import per_run

DATASET, TASK = "sim/lake-depth", "depth"
R_STD = np.sqrt(np.diag(R_FIXED))
Q_DIAG = np.diag(paper_Q()[0])
CH = ("depth", "speed", "pitch")
UNITS = {"depth": "m", "speed": "m/s", "pitch": "rad"}
N = 1000  # particles of GPF, MMPF and PF (000 §3)
# sim/lake-depth's default sensors: their RMS over a 90 s run (base_sigma times the regimes' RMS factor)
GENERATED_RMS = tuple(float(b) / f for b, f in zip(next(p.default for p in make_frame.PARAMS if p.name == "base_sigma"),
                                                   base_for_rms((1.0, 1.0, 1.0))))


def tidy(x: float) -> float:  # a short decimal for commands: 0.006, not 0.006000000000000001
    return float(f"{float(x):.10g}")


MATCHED_R = [tidy(g * g) for g in GENERATED_RMS]  # the generated sensors' mean square noise (an oracle's R)
MAIN = {"GPF": ("gpf", {}), "MMPF": ("mmpf", {}), "EKF": ("ekf", {}), "UKF": ("ukf", {}),
        "PF": ("pf", {"n_particles": N})}
ORACLE = {f"{lab}, R matched": (name, {**p, "R": MATCHED_R}) for lab, (name, p) in MAIN.items() if lab != "GPF"}
ABLATIONS = {  # GPF with one part changed (same filter stream as GPF: common random numbers)
    "GPF without grey particles": ("gpf", {"grey": False}),
    "GPF with the fixed R": ("gpf", {"wavelet": False}),
    "GPF, GM(1,1) eq. 12 derived": ("gpf", {"grey_response": "continuous"}),
    "GPF, GM(1,1) eq. 12 as printed": ("gpf", {"grey_response": "printed"}),
}
VARIANTS = {**MAIN, **ORACLE, **ABLATIONS}


@dataclass(frozen=True)
class Cell:
    noise: float | None  # rho (sensor RMS / fixed R's std); None: as generated
    kappa: float  # Q = kappa * the paper's Q
    profile: int | None = None  # profile_seed; None: the fixed schedule

    def dataset_params(self, duration: float | None = None) -> dict:
        return ({} if self.noise is None else {"noise_rms": [tidy(self.noise * s) for s in R_STD]}) | (
            {} if self.profile is None else {"profile_seed": int(self.profile)}) | (
            {} if duration is None else {"duration": float(duration)})

    def task_params(self) -> dict:
        return {} if self.kappa == 1.0 else {"Q": [tidy(self.kappa * q) for q in Q_DIAG]}

    @property
    def noise_text(self) -> str:
        return "as generated" if self.noise is None else f"{self.noise:g} R"

    @property
    def name(self) -> str:
        return f"sensors {self.noise_text}, κ = {self.kappa:g}, " + (
            "fixed profile" if self.profile is None else f"profile {self.profile}")


def maneuver_mask(problem) -> np.ndarray:
    t = np.asarray(problem.t, float)
    return np.any([(t >= a) & (t < b) for a, b, _ in problem.frame_meta["maneuvers"]], axis=0)


def _segment(res, div, keep) -> dict:
    """Per-run channel RMSE with the reference restricted to ``keep(problem)`` (diverged: +inf)."""
    out = {ch: [] for ch in CH}
    for rec, d in zip(res.records, div):
        p = rec["problem"]
        m = scorer.score_run(dataclasses.replace(p, truth_valid=p.truth_valid & keep(p)), rec["estimates"])
        for ch in CH:
            out[ch].append(np.inf if d else m[f"{ch}_rmse"])
    return {ch: np.asarray(v, float) for ch, v in out.items()}


def compute(job) -> dict:
    """``(cell, labels, runs, seed, duration)`` -> the cell's results; the labels' filters differ."""
    cell, labels, runs, seed, duration = job
    ev = evaluate(DATASET, task=TASK, filters=[VARIANTS[lab][0] for lab in labels], runs=runs, seed=seed,
                  dataset_params=cell.dataset_params(duration), task_params=cell.task_params(),
                  filter_params={VARIANTS[lab][0]: VARIANTS[lab][1] for lab in labels})
    out = {"cell": cell, "seed": seed, "command": command_line(ev.config), "filters": {},
           "t": np.asarray(ev.t, float), "maneuvers": plain(ev.frame_meta["maneuvers"])}
    for lab, res, row in zip(labels, ev.results, ev.rows):
        div = np.array([bool(m["diverged"]) for m in res.runs])
        out["filters"][lab] = {
            "row": plain(row), "lost": per_run(res, "depth_rmse")[1], "rmse": {ch: per_run(res, f"{ch}_rmse")[0]
                                                                               for ch in CH},
            "ess": np.array([e.info.get("mean_ess", np.nan) / N for e in res.estimates]),
            "man": _segment(res, div, maneuver_mask), "level": _segment(res, div, lambda p: ~maneuver_mask(p))}
    return out
