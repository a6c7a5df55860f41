"""Reproduction of paper 001 (AUKF vs UKF, small-AUV dead reckoning in currents), §5 Fig. 3–5.

The paper publishes figures only (no numbers): per-time RMSE of north, east,
depth, body velocity and body acceleration for UKF and AUKF. Its claims:
depth RMSE about equal (the depth gauge dominates); north and east clearly
lower with AUKF; velocity and acceleration lower with AUKF. We run
``sim/sauv-current`` with the DVL in bottom lock (velocity over ground: the
current's effect is measured) and in water track (velocity through the water:
the current is a true unmodelled drift), at current strengths 0.5 and 1.5 m/s
and without current; filters UKF, the paper's AUKF (q̂, p̂, Q̂, R̂) and an AUKF
estimating only Q̂ and R̂ (``adapt_means=none``, the fair adaptive baseline);
a sweep of the forgetting factor b over 0.95–0.99; the ablation of the
estimators and guards; and the UKF with noise-free sensors, the floor that the
unobservable north/east error cannot go below. Every row comes from
:func:`replay.run.evaluation.evaluate`, comparisons paired on the same runs (common
random numbers). Everything not printed in the paper (time step, Q, R, P0,
mission legs, current scale, AHRS error correlation, DVL mode) is documented
in replay/sim/sauv_current.py and replay/models/sauv.py. Layout: :mod:`.p001_doc`.
"""
from __future__ import annotations

from pathlib import Path

from . import p001_doc
from .common5 import run_jobs
from .p001_plan import plan
from .verdict import Stopwatch, footer, write_document


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False, sweep_runs=None):
    """Write ``docs/reproduction/001.md``: ``runs`` Monte Carlo runs (50; quick 2) for the main
    tables, ``sweep_runs`` (30, at most ``runs``) for the forgetting-factor sweep and the ablation."""
    watch = Stopwatch()
    runs = runs or (2 if quick else 50)
    sweep_runs = min(sweep_runs or 30, runs)
    doc = Path(doc or "docs/reproduction/001.md")
    evs = run_jobs(plan(quick, sweep_runs), runs, seed, data_dir, quiet)
    text = p001_doc.render(evs, runs=runs, sweep_runs=sweep_runs, seed=seed, quick=quick, doc=doc)
    command = f"replay reproduce 001 --runs {runs} --seed {seed}" + (" --quick" if quick else "")
    write_document(doc, text + footer(command, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
