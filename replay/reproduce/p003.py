"""Reproduction of paper 003 (weight-factor PF vs PF, UAV formation under glint noise), §4 Fig. 1–6.

The experiments are data (:mod:`.p003_plan`), the claims and their rules are declared before the
run (:mod:`.p003_claims`), the prose is ``replay/papers/003.md``; this module runs the evaluations
(:func:`replay.run.evaluation.evaluate`, in ``REPLAY_WORKERS`` processes), builds the evidence (per-run
values paired on the same measurements), decides (:func:`replay.reproduce.rules.decide`) and
renders (:func:`replay.reproduce.render.render`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from replay.run.evaluation import evaluate

from . import p003_tables as tables
from .p003_claims import CLAIMS
from .p003_plan import GRIDS, SETTINGS, TUNE_RUNS, TUNED, plan, row_job, tune_plan
from replay.campaign.longest import pool, run_longest_first, workers
from .render import render
from .rules import decide
from replay.util.portable import write_document

from .verdict import Stopwatch, footer


def _evaluate(args):
    """One job's evaluation (what a worker process runs)."""
    j, seed, data_dir = args
    return evaluate(
        j.dataset,
        filters=j.filters,
        runs=j.runs,
        seed=seed + j.seed,
        data_dir=data_dir,
        dataset_params=j.dataset_params or None,
        filter_params=j.filter_params,
        task_params=j.task_params or None,
    )


def compute(jobs, runs, seed, data_dir, ex, quiet) -> dict:
    """``{key: Evaluation}`` of ``jobs`` (``runs`` where a job names none), the costliest first."""
    for j in jobs:
        j.runs = j.runs or runs
    cost = [j.runs * sum(p.get("n_particles", 30) for p in j.filter_params.values()) for j in jobs]
    done = dict(
        run_longest_first(
            _evaluate,
            [(j, seed, data_dir) for j in jobs],
            cost,
            [f"{j.key} ({j.runs} runs)" for j in jobs],
            ex,
            quiet,
            "003: ",
        )
    )
    return {j.key: done[i] for i, j in enumerate(jobs)}


def tuned_jobs(evs: dict) -> tuple[list, dict]:
    """The test evaluations of each baseline at its grid's best (lowest mean position RMSE on the
    tuning seeds), keyed ``tuned|<setting>|<filter>``, and {(setting, filter): (value, score)}."""
    jobs, best = [], {}
    for s in SETTINGS:
        if s[0] not in TUNED:
            continue
        for name, (_, grid) in GRIDS.items():
            scores = [float(evs[f"tune|{s[0]}|{name}|{v}"].rows[0]["pos_rmse"]) for v in grid]
            i = int(np.nanargmin(scores))
            best[(s[0], name)] = grid[i], scores[i], dict(zip(grid, scores))
            jobs.append(row_job(f"tuned|{s[0]}|{name}", s, "a=1.0" if name == "wf-pf" else name, grid[i]))
    return jobs, best


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Write ``docs/reproduction/003.md`` (``runs`` Monte Carlo runs per row: 100, quick 4)."""
    watch = Stopwatch()
    runs = runs or (4 if quick else 100)
    doc = Path(doc or "docs/reproduction/003.md")
    with pool(workers()) as ex:
        evs = compute(plan() + tune_plan(min(TUNE_RUNS, runs)), runs, seed, data_dir, ex, quiet)
        more, best = tuned_jobs(evs)
        evs |= compute(more, runs, seed, data_dir, ex, quiet)
    evid = tables.evidence(evs)
    verdicts = decide(CLAIMS, evid, seed=seed)
    fields = tables.fields(evs, best, runs, doc, verdicts, evid)
    command = f"replay reproduce 003 --runs {runs} --seed {seed}" + (" --quick" if quick else "")
    fields["command"] = command
    write_document(doc, render("003", fields, verdicts) + footer(command, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
