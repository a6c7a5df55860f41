"""The experiments of the paper-003 reproduction (:mod:`.p003`) as data: settings, rows, grids.

A **setting** is one line of :data:`SETTINGS`: its label, dataset and task parameters, the particle
count, the α values of the WF-PF rows, the extra filters (``pf`` the bootstrap PF on its own
particle stream, ``rough`` the PF with roughening K = 0.2, ``ukf``, ``ekf``, ``nofloor`` the α = 0.5
row without the 1e−99 floor) and the seed offsets it runs on (the document's seed s plus the fresh
seeds of the pooled verdicts). Adding an ablation is a line here. :data:`GRIDS`: the declared grid
over each baseline's noise scale, tuned on the seeds s + :data:`TUNE_SEED` (:data:`TUNE_RUNS` runs,
mean position RMSE) and scored on seed s (item 3 of issue 27).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .common5 import Job

DS = "sim/uav-formation"
SIGMA1 = 0.4 * np.pi / 180  # 003 §4.1
POOLED = (0, 1, 2, 3)  # seed offsets of the pooled verdicts: s and three fresh seeds
POOLED_ROWS = ("a=1.0", "a=0.75", "a=0.5", "pf", "ukf")  # the rows the verdicts compare (others: seed s)
ROUGHENING = 0.2
TUNE_SEED, TUNE_RUNS = 100, 50


def glint(ratio, eps):
    return {"sigma2": ratio * SIGMA1, "eps": eps}


CORE, WIDE = {"eps": 0.0}, {"eps": 1.0}  # task eps: the mismatched Gaussian the filter assumes
WHAT = {0.0: "filter assumes the thermal core N(0, σ₁²)", 1.0: "filter assumes the glint component N(0, σ₂²)"}
# label, dataset params, task params, N, WF-PF alphas (besides α = 1), extra rows, seed offsets, table
SETTINGS = [
    ("printed", {}, {}, 1000, (0.75, 0.5, 0.25), ("pf", "rough", "ukf", "ekf"), POOLED, "printed"),
    *[(f"N = {n}", {}, {}, n, (0.75, 0.5), ("pf",), (0,), "N") for n in (50, 100, 200, 500)],
    ("σ_a = 0.03", {"accel_sigma": 0.03}, {}, 100, (0.75, 0.5), ("pf", "rough", "ukf", "ekf"), POOLED, "Q"),
    *[(f"σ_a = {s}", {"accel_sigma": s}, {}, 100, (0.75, 0.5), ("pf", "rough"), (0,), "Q") for s in (0.1, 0.3)],
    ("σ_a = 1.0", {}, {}, 100, (0.75, 0.5), ("pf", "rough"), (0,), "Q"),
    *[
        (f"σ₂/σ₁ = {r}, ε = {e}", glint(r, e), {}, 100, (0.75, 0.5), ("pf", "ukf"), (0,), "contrast")
        for r, e in ((5, 0.05), (5, 0.3), (10, 0.05), (10, 0.1), (10, 0.3))
    ],
    *[
        (f"σ₂/σ₁ = {r}, ε = {e}, {WHAT[t['eps']]}", glint(r, e), t, 100, a, ("pf", "nofloor"), (0,), "mismatch")
        for r, e, t, a in (
            (5, 0.3, CORE, (0.75, 0.5, 0.25)),
            (10, 0.1, CORE, (0.75, 0.5, 0.25)),
            (10, 0.1, WIDE, (0.75, 0.5)),
        )
    ],
]
TUNED = ("printed", "σ_a = 0.03")  # the settings whose baselines are tuned
GRIDS = {  # filter: (parameter, grid); ``rough`` is the pf's roughening constant K
    "pf": ("q_scale", (1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0)),
    "rough": ("roughening", (0.05, 0.1, 0.2, 0.4, 0.8)),
    "ukf": ("q_scale", (0.5, 1.0, 2.0, 4.0)),
    "ekf": ("q_scale", (0.5, 1.0, 2.0, 4.0)),
    "wf-pf": ("alpha", (1.0, 0.75, 0.5, 0.25, 0.1)),
}


@dataclass
class SeededJob(Job):
    """A :class:`Job` on the document's seed plus ``seed`` (an offset)."""

    seed: int = 0


def row_job(key, setting, name, value=None, seed=0, runs=0) -> Job:
    """The evaluation of one row: ``name`` is ``a=<α>`` (WF-PF), pf, rough, ukf, ekf or nofloor;
    ``value`` a tuned parameter (of :data:`GRIDS`)."""
    _, data, task, n, *_ = setting
    if name.startswith("a="):
        flt, params = "wf-pf", {"n_particles": n, "alpha": float(name[2:])}
    elif name == "nofloor":
        flt, params = "wf-pf", {"n_particles": n, "alpha": 0.5, "weight_floor": 1e-300}
    else:
        flt = "pf" if name == "rough" else name
        params = {"n_particles": n} if flt == "pf" else {}
        params |= {"roughening": ROUGHENING} if name == "rough" else {}
    if value is not None:
        params[GRIDS["wf-pf" if flt == "wf-pf" else name][0]] = value
    return SeededJob(key, DS, (flt,), dict(data), {flt: params}, dict(task), runs, seed)


def rows(setting) -> list[str]:
    return ["a=1.0"] + [f"a={a}" for a in setting[4]] + list(setting[5])


def plan() -> list[Job]:
    """Every evaluation of the settings, keyed ``<label>|<row>|<seed offset>``."""
    return [
        row_job(f"{s[0]}|{r}|{k}", s, r, seed=k)
        for s in SETTINGS
        for r in rows(s)
        for k in (s[6] if r in POOLED_ROWS else (0,))
    ]


def tune_plan(runs: int = TUNE_RUNS) -> list[Job]:
    """The grid evaluations on the tuning seeds, keyed ``tune|<setting>|<filter>|<value>`` (``runs`` each)."""
    out = []
    for s in SETTINGS:
        if s[0] in TUNED:
            for name, (_, grid) in GRIDS.items():
                r = "a=1.0" if name == "wf-pf" else name
                out += [row_job(f"tune|{s[0]}|{name}|{v}", s, r, v, TUNE_SEED, runs) for v in grid]
    return out
