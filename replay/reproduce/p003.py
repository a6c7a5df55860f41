"""Reproduction of paper 003 (weight-factor PF vs PF, UAV formation under glint noise), §4 Fig. 1–6.

The paper publishes figures only: the standard PF's position error drifts up
to about 16 m (x) and 15 m (y); the weight-factor PF (α = 0.75) stays clearly
smaller, without drift. At the printed setting (glint σ₂/σ₁ = 2 on the
bearing, ε = 0.75, the filter knows the mixture, N = 1000) the glint is
nearly Gaussian and no effect of α can show, so besides that setting the
document sweeps what could make α matter: the particle count N, the process
noise (small values impoverish the cloud), the glint contrast σ₂/σ₁ and
probability ε, and a PF whose Gaussian likelihood is mismatched to the glint
(task parameter ``eps`` = 0: the thermal core only; 1: the glint component
only). Baselines: the bootstrap PF (α = 1, no floor), the WF-PF with α = 1
(the 1e−99 weight floor alone), a PF with roughening (the textbook remedy for
impoverishment), UKF and EKF. Every row comes from
:func:`replay.run.evaluation.evaluate`; comparisons are paired on the same runs
(common random numbers). Table layout and plots: :mod:`.p003_doc`.
"""
from __future__ import annotations

from pathlib import Path

from . import p003_doc
from .common5 import run_jobs
from .p003_plan import plan
from .verdict import Stopwatch, footer, write_document


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Write ``docs/reproduction/003.md`` (``runs`` Monte Carlo runs per configuration: 100, quick 4)."""
    watch = Stopwatch()
    runs = runs or (4 if quick else 100)
    doc = Path(doc or "docs/reproduction/003.md")
    evs = run_jobs(plan(), runs, seed, data_dir, quiet)
    text = p003_doc.render(evs, runs=runs, seed=seed, quick=quick, doc=doc)
    command = f"replay reproduce 003 --runs {runs} --seed {seed}" + (" --quick" if quick else "")
    write_document(doc, text + footer(command, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
