"""The evaluations of the paper-001 reproduction (:mod:`.p001`): settings and the job list."""
from __future__ import annotations

from .common5 import Job

DS = "sim/sauv-current"
TRACK = {"bottom": "bottom-lock DVL", "water": "water-track DVL"}
TRACKS = ("bottom", "water")
STRENGTHS = (0.5, 1.5)
B_SWEEP = (0.95, 0.97, 0.99)  # 0.98 (the default) is the main table's row
QR = {"adapt_means": "none"}  # the AUKF estimating only Q-hat and R-hat
NOISE_FREE = {"dvl_percent": 0.0, "ahrs_sigma_deg": 0.0, "acc_bias": 0.0, "acc_noise_density": 0.0}
# AUKF variants of the ablation (filters/p001/aukf.py); the paper's and Q-hat, R-hat only are main rows
ABLATION = [("guard previous", {"guard": "previous"}),
            ("guard clip", {"guard": "clip"}),
            ("R̂ only", {"adapt_means": "none", "adapt_q": False}),
            ("Q̂ only", {"adapt_means": "none", "adapt_r": False}),
            ("Q̂ only, guard previous", {"adapt_means": "none", "adapt_r": False, "guard": "previous"}),
            ("p̂ only", {"adapt_means": "p", "adapt_q": False, "adapt_r": False}),
            ("q̂ only", {"adapt_means": "q", "adapt_q": False, "adapt_r": False})]
# in water track only the variants that could absorb a drift (q-hat) and the best of bottom lock
ABLATION_WATER = ("q̂ only", "Q̂ only, guard previous")
TRACE_RUNS = 10


def data(track: str, strength: float, **extra) -> dict:
    return {"dvl_track": track, "strength": strength, **extra}


def plan(quick: bool, sweep_runs: int) -> list[Job]:
    """Every evaluation of the document, in order (keys are read by :mod:`.p001_doc`)."""
    strengths = STRENGTHS[:1] if quick else STRENGTHS
    b_sweep = (B_SWEEP[0], B_SWEEP[-1]) if quick else B_SWEEP
    jobs = []
    for track in TRACKS:
        for s in strengths:
            d = data(track, s)
            jobs += [Job(f"{track} {s}", DS, ("ukf", "aukf"), d),
                     Job(f"{track} {s} QR", DS, ("aukf",), d, {"aukf": QR})]
    d = data("bottom", 0.0)
    jobs += [Job("no current", DS, ("ukf", "aukf"), d), Job("no current QR", DS, ("aukf",), d, {"aukf": QR})]
    for track in TRACKS:
        jobs.append(Job(f"{track} noise-free", DS, ("ukf",), data(track, 0.5, **NOISE_FREE)))
    for track in TRACKS:
        for b in b_sweep:
            jobs += [Job(f"{track} b={b}", DS, ("aukf",), data(track, 0.5), {"aukf": {"forgetting": b}},
                         runs=sweep_runs),
                     Job(f"{track} b={b} QR", DS, ("aukf",), data(track, 0.5), {"aukf": dict(QR, forgetting=b)},
                         runs=sweep_runs)]
    for track in TRACKS[:1] if quick else TRACKS:
        jobs += [Job(f"{track} ablation {name}", DS, ("aukf",), data(track, 0.5), {"aukf": p}, runs=sweep_runs)
                 for name, p in ABLATION if track == "bottom" or name in ABLATION_WATER]
    # where q-hat points without any current (is its drift an estimate of the current?)
    jobs.append(Job("no current ablation q̂ only", DS, ("aukf",), data("bottom", 0.0),
                    {"aukf": dict(ABLATION)["q̂ only"]}, runs=sweep_runs))
    jobs.append(Job("traces", DS, ("aukf",), data("bottom", 0.5), {"aukf": {"keep_history": True}},
                    runs=min(TRACE_RUNS, sweep_runs)))
    return jobs
