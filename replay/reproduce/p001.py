"""Reproduction of paper 001 (AUKF vs UKF, small-AUV dead reckoning in currents), §5 Fig. 3–5.

The paper publishes figures only: per-time RMSE of north, east, depth, body velocity and
acceleration for UKF and AUKF. The experiments, the claims and their rules are data in
:mod:`.p001_plan`; the prose is ``replay/papers/001.md``, filled by the one renderer
(:mod:`.render`); every row comes from :func:`replay.run.evaluation.evaluate` (the pipeline of
``replay eval``), comparisons paired on the same runs (common random numbers). Everything the
paper does not print (time step, Q, R, P0, mission legs, current scale, DVL mode) is documented in
replay/sim/sauv_current.py and replay/models/sauv.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from replay.util.errors import ReplayError

from . import p001_plan as plan
from .common5 import combine, commands, row, run_jobs, table
from .p001_plots import TRACK, plots
from .render import found, render, table as md
from .rules import Comparison, decide, per_run
from replay.util.portable import write_document

from .verdict import Stopwatch, footer

OLD = {
    "depth": "deviation explained",
    "north": "deviation explained",
    "east": "deviation explained",
    "velocity": "deviation explained",
    "acceleration": "deviation explained",
    "current": "deviation explained",
    "premise": "(new row)",
}


def pick(evs) -> dict:
    """The tuned UKF's scales by the declared rule (:data:`.p001_plan.TUNE_TIE`) and the grid's rows."""
    grid = [(q, r, evs[f"tune q{q} r{r}"].rows[0]) for q in plan.Q_SCALES for r in plan.R_SCALES]
    score = {
        (q, r): x["pos_rmse"] if not x.get("diverged") and np.isfinite(float(x["pos_rmse"])) else np.inf
        for q, r, x in grid
    }  # as `replay tune`: a diverged run scores inf
    best = min(score.values())
    if not np.isfinite(best):
        raise ReplayError("001 tuning: every grid point of the UKF diverged on the training seeds")
    near = [g for g in grid if score[g[:2]] <= (1 + plan.TUNE_TIE) * best]
    q, r, _ = min(near, key=lambda g: abs(float(g[2]["anees"] or np.inf) - 3.0))
    rows = [
        [
            f"{a:g}",
            f"{b:g}",
            f"{x['pos_rmse']:.3f}",
            f"{float(x['anees'] or np.nan):.1f}",
            "**chosen**" if (a, b) == (q, r) else "",
        ]
        for a, b, x in grid
    ]
    return {"q_scale": q, "r_scale": r}, md(["q_scale", "r_scale", "pos_rmse (training seeds)", "ANEES", ""], rows)


def cmp(name, ra, rb, metric, fa=1.0, fb=1.0):
    """Comparison "fa × ``ra`` < fb × ``rb``" of ``metric`` per run (results of the same runs)."""
    (a, la), (b, lb) = per_run(ra, metric), per_run(rb, metric)
    return Comparison(name, fa * a, fb * b, la, lb)


def evidence(evs, n) -> dict:
    prim = evs[plan.key(*plan.PRIMARY)]
    u, a = prim.results
    u30 = prim.first(n).results[0]
    abl = {k: evs[f"bottom ablation {k}"].results[0] for k in ("p̂ only", "R̂ only", "Q̂ only")}
    out = {
        "depth": [
            cmp("depth, AUKF < 1.2 × UKF", a, u, "depth_rmse", fb=1 + plan.MARGIN),
            cmp("depth, 0.8 × UKF < AUKF", u, a, "depth_rmse", fa=1 - plan.MARGIN),
        ],
        "north": [cmp("north", a, u, "north_rmse")],
        "east": [cmp("east", a, u, "east_rmse")],
    }
    for claim, chans in (("depth", ("depth",)), ("velocity", plan.CH[3:6]), ("acceleration", plan.CH[6:])):
        out.setdefault(claim, [cmp(c, a, u, f"{c}_rmse") for c in chans])
        out[f"{claim} why"] = [
            x
            for c in chans
            for x in (
                cmp(f"{c}: UKF < p̂ only", u30, abl["p̂ only"], f"{c}_rmse"),
                cmp(f"{c}: UKF < R̂ only", u30, abl["R̂ only"], f"{c}_rmse"),
                cmp(f"{c}: Q̂ only < 1.2 × UKF", abl["Q̂ only"], u30, f"{c}_rmse", fb=1 + plan.MARGIN),
            )
        ]
    water = [k for k in ("water 0.5", "water 1.5") if k in evs]
    out["current"] = [cmp(f"{k} m/s", evs[k].results[1], evs[k].results[0], "pos_rmse") for k in water]
    out["current why"] = [
        cmp(
            "noise-free UKF, bottom < water",
            evs["bottom noise-free"].results[0],
            evs["water noise-free"].results[0],
            "pos_rmse",
        )
    ]
    mt, lin, lw = evs["mistuned"], evs["linear"], evs["linear wrong R"]
    out["premise"] = [cmp("R × 100: AUKF < UKF", mt.results[1], mt.results[0], "pos_rmse")]
    out["premise why"] = [
        cmp("true Q, R: UKF < Q̂R̂ AUKF", lin.results[0], lin.results[1], "pos_rmse"),
        cmp("R × 100: R̂ only < Q̂R̂ AUKF", evs["linear wrong R, R̂ only"].results[0], lw.results[1], "pos_rmse"),
    ]
    return out


def cell_rows(evs, k, tuned_label):
    items = [
        ("UKF", row(evs[k], "ukf")),
        (tuned_label, row(evs[f"{k} tuned"])),
        ("AUKF (paper: q̂, p̂, Q̂, R̂)", row(evs[k], "aukf")),
        ("AUKF (Q̂, R̂ only)", row(evs[f"{k} QR"])),
    ]
    return combine(items, metrics=plan.ALL)


def nees_table(rows) -> str:
    f = lambda r, k: f"{float(r[k]):.3g}" if np.isfinite(float(r.get(k) or np.nan)) else "n/a"  # noqa: E731
    return md(
        ["filter", "ANEES (position, 3 dof)", "95 % band", "steps inside", "flag", "ANIS"],
        [
            [
                r["label"],
                f(r, "anees"),
                f"[{f(r, 'anees_lo')}, {f(r, 'anees_hi')}]",
                f(r, "anees_inside"),
                r.get("anees_flag", ""),
                f(r, "anis"),
            ]
            for r in rows
        ],
    )


def tab(items, metrics=plan.ALL, paired=plan.POS) -> str:
    rows = combine(items, metrics=metrics)
    return table(rows, metrics=metrics, paired_metrics=paired) + "\n\nCommands:\n\n" + commands(rows)


def final(ev, i, name, j, absolute):
    """Mean over runs of the final estimate ``name`` (info of result ``i``; a matrix: its mean diagonal)."""
    v = [np.atleast_1d(np.asarray(e.info[name], float)) for e in ev.results[i].estimates]
    v = [np.diagonal(x) if x.ndim == 2 else x for x in v]
    v = [np.abs(x) if absolute else x for x in v]
    return float(np.mean([x.mean() if j is None else x[j] for x in v]))


def spec_table(evs, n, metrics, paired, rows, cut, info) -> str:
    """One of :data:`.p001_plan.TABLES`: the rows' results, then their final estimates."""
    items = [(lab, (evs[k].first(n) if cut else evs[k], i)) for lab, k, i in rows if k in evs]
    out = [tab(items, metrics, paired)] if metrics else []
    est = [(lab, ev, i) for lab, (ev, i) in items if ev.results[i].name == "aukf"]
    if info:
        out.append(
            md(
                ["filter"] + [c[0] for c in info],
                [[lab] + [format(final(ev, i, *c[1:3], c[4]), c[3]) for c in info] for lab, ev, i in est],
            )
        )
    return "\n\n".join(out)


def fields(evs, verdicts, runs, seed, n, tuned, grid, quick, doc):
    tl = f"UKF tuned (q × {tuned['q_scale']:g}, r × {tuned['r_scale']:g})"
    cells = [k for k in (plan.key(*c) for c in plan.CELLS) if k in evs]
    sect = {
        k: "### no current" if k == "no current" else f"### {TRACK[k.split()[0]]}, current {k.split()[1]} m/s"
        for k in cells
    }
    prim = cell_rows(evs, plan.key(*plan.PRIMARY), tl)
    f = {
        "runs": runs,
        "n": n,
        "tuned": tl,
        "grid": grid,
        "tune_runs": plan.TUNE_RUNS,
        "primary": table(prim, metrics=plan.ALL),
        "nees": nees_table(prim),
        "commands": commands(prim),
        "cells": "\n\n".join(
            f"{sect[k]}\n\n"
            + table(r := cell_rows(evs, k, tl), metrics=plan.ALL)
            + "\n\n"
            + nees_table(r)
            + "\n\nCommands:\n\n"
            + commands(r)
            for k in cells
        ),
        "relabel": md(
            ["claim", "old label", "new label", "the numbers behind it"],
            [[v.claim.id, OLD[v.claim.id], v.label, found(v)] for v in verdicts],
        ),
        "quick": " --quick" if quick else "",
        "seed": seed,
        "plots": plots(evs, doc),
    }
    return f | {name: spec_table(evs, n, *spec) for name, spec in plan.TABLES.items()}


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False, sweep_runs=None):
    """Write ``docs/reproduction/001.md``: ``runs`` Monte Carlo runs (50; quick 4) for the main
    tables, ``sweep_runs`` (30, at most ``runs``) for the forgetting-factor sweep and the ablation."""
    watch = Stopwatch()
    runs = runs or (4 if quick else 50)
    n = min(sweep_runs or 30, runs)
    doc = Path(doc or "docs/reproduction/001.md")
    tuned, grid = pick(run_jobs(plan.tuning_jobs(runs), runs, seed + 1, data_dir, quiet))
    evs = run_jobs(plan.jobs(quick, n, tuned), runs, seed, data_dir, quiet)
    verdicts = decide(plan.CLAIMS, evidence(evs, n), seed=seed)
    text = render("001", fields(evs, verdicts, runs, seed, n, tuned, grid, quick, doc), verdicts)
    command = f"replay reproduce 001 --runs {runs} --seed {seed}" + (" --quick" if quick else "")
    write_document(doc, text + footer(command, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
