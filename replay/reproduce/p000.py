"""``replay reproduce 000``: GPF vs MMPF vs EKF on synthetic lake-trial logs (paper 000), as data + a template.

The experiments (:mod:`replay.reproduce.p000_cells`): a grid of sensor level × κ on the fixed
schedule, random maneuver schedules, GPF ablations, every filter (and the baselines with R
matched to the sensors) on a **tuning seed** (master seed + 1) to pick each filter's best
setting, then compared on the verdict seed. The claims and their rules are :data:`CLAIMS`,
declared before the run; :func:`evidence` fills the comparisons the rules name; the verdicts
come from :func:`replay.reproduce.rules.decide`; the prose is ``replay/papers/000.md``.
``quick``: 20 s logs, 2 runs, a 3 × 2 grid, 2 profiles (a smoke check of the path).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from . import render
from .render import fmt, pm
from .p000_cells import ABLATIONS, CH, GENERATED_RMS, MAIN, ORACLE, R_STD, UNITS, Cell, compute
from replay.campaign.longest import pool, run_longest_first, workers as pool_workers
from .rules import Claim, Comparison, decide
from replay.util.portable import write_document

from .verdict import Stopwatch, footer, result_rows
from replay.reproduce.p000_claims import CLAIMS, OLD, EVIDENCE

NOISES, KAPPAS, PROFILES, PROFILE_KAPPAS = (None, 0.03, 0.3, 1.0), (1.0, 1e-2, 1e-4), (1, 2, 3, 4, 5, 6), (1.0, 1e-4)
PAPER, MISMATCH = Cell(None, 1.0), Cell(None, 1e-4)
ABLATION_CELLS = (PAPER, MISMATCH, Cell(1.0, 1e-4))
RUNS, PROFILE_RUNS, TUNE_RUNS = 8, 5, 8  # per grid/ablation cell, per profile cell, per tuning cell
QUICK = {
    "runs": 2,
    "duration": 20.0,
    "noises": (None, 0.3, 1.0),
    "kappas": (1.0, 1e-4),
    "profiles": (1, 2),
    "profile_kappas": (1e-4,),
    "ablation_cells": (PAPER, MISMATCH),
}
OTHERS = ("MMPF", "EKF", "UKF", "PF")


def plan(runs=None, quick=False) -> dict:
    q = QUICK if quick else {}
    runs = runs or q.get("runs", RUNS)
    p = {
        "runs": runs,
        "profile_runs": max(2, round(runs * PROFILE_RUNS / RUNS)),
        "duration": q.get("duration"),
        "tune_runs": max(2, round(runs * TUNE_RUNS / RUNS)),
        "noises": q.get("noises", NOISES),
        "kappas": q.get("kappas", KAPPAS),
        "ablation": list(q.get("ablation_cells", ABLATION_CELLS)),
    }
    p["grid"] = [Cell(n, k) for n in p["noises"] for k in p["kappas"]]
    p["profiles"] = [
        Cell(None, k, s) for k in q.get("profile_kappas", PROFILE_KAPPAS) for s in q.get("profiles", PROFILES)
    ]
    oracle = [c for c in p["grid"] if c.noise is None]
    p["jobs"] = (
        [(c, tuple(MAIN), runs, 0) for c in p["grid"]]
        + [(c, tuple(MAIN), p["tune_runs"], 1) for c in p["grid"]]
        + [(c, tuple(ORACLE), n, s) for c in oracle for n, s in ((runs, 0), (p["tune_runs"], 1))]
        + [(c, tuple(MAIN), p["profile_runs"], 0) for c in p["profiles"]]
        + [(c, (lab,), runs, 0) for c in p["ablation"] for lab in ABLATIONS]
    )
    return p


def _mean(v) -> float:
    return float(np.mean(v)) if len(v) else float("nan")


def order(r: dict, ch: str) -> str:
    """GPF − MMPF / MMPF − EKF of a cell (paired)."""
    return f"{pm(r['GPF']['rmse'][ch], r['MMPF']['rmse'][ch])} / {pm(r['MMPF']['rmse'][ch], r['EKF']['rmse'][ch])}"


def cmp(name, fa, fb, key="rmse", ch="depth") -> Comparison:
    return Comparison(name, fa[key][ch], fb[key][ch], fa["lost"], fb["lost"])


def ratio(f, ch):
    with np.errstate(all="ignore"):
        return {"r": {ch: f["man"][ch] / f["level"][ch]}, "lost": f["lost"]}


def lead(res: dict, ch: str) -> dict:
    """Per-run lead of GPF over the baseline with the lowest mean RMSE in the cell: 1 − GPF / best."""
    best = min(OTHERS, key=lambda lab: _mean(res[lab]["rmse"][ch]))
    with np.errstate(all="ignore"):
        return {
            "v": {ch: 1 - res["GPF"]["rmse"][ch] / res[best]["rmse"][ch]},
            "lost": res["GPF"]["lost"] | res[best]["lost"],
            "best": best,
        }


def tuned(T: dict, grid, noise) -> dict:
    """(label, channel) -> the setting (cell, variant label) with the lowest mean RMSE on the tuning seed."""
    out = {}
    for lab in MAIN:
        options = [(c, v) for c in grid if c.noise == noise for v in (lab, f"{lab}, R matched") if v in T[c]]
        for ch in CH:
            out[(lab, ch)] = min(options, key=lambda o: _mean(T[o[0]][o[1]]["rmse"][ch]))
    return out


def _best_evidence(R: dict, T: dict, grid) -> list:
    """GPF − each other filter, every one at its setting tuned on the tuning seed."""
    best = tuned(T, grid, None)
    return [
        cmp(
            f"{ch}: GPF − {lab}",
            R[best[("GPF", ch)][0]][best[("GPF", ch)][1]],
            R[best[(lab, ch)][0]][best[(lab, ch)][1]],
            ch=ch,
        )
        for ch in CH
        for lab in OTHERS
    ]


def _cell_evidence(r: dict, cell: Cell, tag: str) -> dict:
    """The order, the worst maneuver errors and the degradation under maneuvers in one key cell."""
    ev = {}
    for ch in CH:
        ev[f"{ch}@{tag}"] = [
            cmp(f"κ = {cell.kappa:g}: GPF − MMPF", r["GPF"], r["MMPF"], ch=ch),
            cmp(f"κ = {cell.kappa:g}: MMPF − EKF", r["MMPF"], r["EKF"], ch=ch),
        ]
    ev[f"worst@{tag}"] = [
        cmp(f"κ = {cell.kappa:g}, {ch}: {lab} − EKF", r[lab], r["EKF"], "man", ch)
        for ch in CH
        for lab in ("GPF", "MMPF")
    ]
    ev[f"degrades@{tag}"] = [
        cmp(f"κ = {cell.kappa:g}, {ch}: {lab} − EKF", ratio(r[lab], ch), ratio(r["EKF"], ch), "r", ch)
        for ch in CH
        for lab in ("GPF", "MMPF")
    ]
    return ev


def _lead_evidence(R: dict, p: dict) -> dict:
    """GPF's lead over the best baseline: across κ per sensor level (lead-q), across sensor levels per κ (lead-r)."""
    noises, kappas = [n for n in p["noises"] if n is not None], p["kappas"]
    cell = {(c.noise, c.kappa): R[c] for c in p["grid"]}
    return {
        "lead-q": [
            cmp(
                f"sensors {Cell(n, 1).noise_text}, {ch}",
                lead(cell[(n, kappas[0])], ch),
                lead(cell[(n, kappas[-1])], ch),
                "v",
                ch,
            )
            for n in p["noises"]
            for ch in CH
        ],
        "lead-r": [
            cmp(f"κ = {k:g}, {ch}", lead(cell[(max(noises), k)], ch), lead(cell[(min(noises), k)], ch), "v", ch)
            for k in kappas
            for ch in CH
        ],
    }


def _ablation_evidence(R: dict, ablation) -> dict:
    """GPF − GPF without grey particles (κ < 1 cells), GPF − GPF with the fixed R (every ablation cell)."""
    name = lambda c, ch: f"sensors {c.noise_text}, κ = {c.kappa:g}, {ch}"
    return {
        "grey": [
            cmp(name(c, ch), R[c]["GPF"], R[c]["GPF without grey particles"], ch=ch)
            for c in ablation
            if c.kappa < 1
            for ch in CH
        ],
        "wavelet": [cmp(name(c, ch), R[c]["GPF"], R[c]["GPF with the fixed R"], ch=ch) for c in ablation for ch in CH],
    }


def evidence(R: dict, T: dict, p: dict) -> dict:
    """The comparisons every rule of :data:`CLAIMS` names (``R``: verdict seed, ``T``: tuning seed)."""
    ev, grid = {"best": _best_evidence(R, T, p["grid"])}, p["grid"]
    for cell, tag in ((PAPER, "paper"), (MISMATCH, "mismatch")):
        ev.update(_cell_evidence(R[cell], cell, tag))
    for ch in CH:
        ev[f"{ch}@fixedR"] = [
            cmp(f"{ch}: GPF with the fixed R − GPF", R[PAPER]["GPF with the fixed R"], R[PAPER]["GPF"], ch=ch)
        ]
    us = {lab: [R[c][lab]["row"]["us_per_step"] for c in grid] for lab in ("GPF", "MMPF")}
    ev["cost"] = [Comparison("GPF − MMPF, µs per step over the grid cells", us["GPF"], us["MMPF"])]
    ev.update(_lead_evidence(R, p))
    ev.update(_ablation_evidence(R, p["ablation"]))
    return ev


def _table_best(R: dict, T: dict, grid) -> str:
    """Each filter at its tuned setting, per channel, and GPF − the best other filter."""
    best = tuned(T, grid, None)
    at = {(lab, ch): R[best[(lab, ch)][0]][best[(lab, ch)][1]]["rmse"][ch] for lab in MAIN for ch in CH}
    other = {ch: min(OTHERS, key=lambda lab: _mean(at[(lab, ch)])) for ch in CH}
    return render.table(
        ["channel", *MAIN, "GPF − the best other (paired)"],
        [
            [render.anchor_tag("#e-best") * (ch == "depth") + ch]
            + [
                f"{fmt(_mean(at[(lab, ch)]))} (κ = {best[(lab, ch)][0].kappa:g}"
                f"{', R matched' * ('R m' in best[(lab, ch)][1])})"
                for lab in MAIN
            ]
            + [f"{pm(at[('GPF', ch)], at[(other[ch], ch)])} ({other[ch]})"]
            for ch in CH
        ],
    )


def _table_order(R: dict, grid) -> str:
    """GPF − MMPF / MMPF − EKF in every grid cell."""
    return render.table(
        ["sensors", "κ", *[f"{ch}: GPF − MMPF / MMPF − EKF" for ch in CH]],
        [
            [render.anchor_tag("#e-order") * (c == PAPER) + c.noise_text, f"{c.kappa:g}"]
            + [order(R[c], ch) for ch in CH]
            for c in grid
        ],
    )


def _table_maneuvers(R: dict, grid) -> str:
    """Errors during maneuvers, on level legs, and their ratio, in the key cells."""
    filters, key = ("GPF", "MMPF", "EKF"), [c for c in (PAPER, MISMATCH) if c in grid]
    return render.table(
        ["cell", "channel", "maneuvers GPF / MMPF / EKF", "level GPF / MMPF / EKF", "ratio GPF / MMPF / EKF"],
        [
            [render.anchor_tag("#e-man") * (c == PAPER and ch == "depth") + c.name, ch]
            + [" / ".join(fmt(_mean(R[c][lab][k][ch])) for lab in filters) for k in ("man", "level")]
            + [" / ".join(f"{np.mean(ratio(R[c][lab], ch)['r'][ch]):.2f}" for lab in filters)]
            for c in key
            for ch in CH
        ],
    )


def _table_ablation(R: dict, ablation) -> str:
    """Each GPF variant − GPF in the ablation cells."""
    return render.table(
        ["cell", "variant", *[f"{ch}: variant − GPF" for ch in CH]],
        [
            [
                render.anchor_tag("#e-ablation") * (c == ablation[0] and lab == "GPF without grey particles") + c.name,
                lab,
            ]
            + [pm(R[c][lab]["rmse"][ch], R[c]["GPF"]["rmse"][ch]) for ch in CH]
            for c in ablation
            for lab in ABLATIONS
        ],
    )


def _table_lead(R: dict, grid) -> str:
    """GPF's mean lead over the best baseline in every grid cell."""
    return render.table(
        ["sensors", "κ", *CH],
        [
            [render.anchor_tag("#e-lead") * (c == grid[0]) + c.noise_text, f"{c.kappa:g}"]
            + [f"{100 * np.nanmean(lead(R[c], ch)['v'][ch]):+.0f} % ({lead(R[c], ch)['best']})" for ch in CH]
            for c in grid
        ],
    )


def _table_ess(R: dict, grid) -> str:
    """Mean ESS/N and lost runs of the particle filters in every grid cell."""
    filters = ("GPF", "MMPF", "PF")
    return render.table(
        ["sensors", "κ", "ESS/N GPF", "ESS/N MMPF", "ESS/N PF", "lost GPF / MMPF / PF"],
        [
            [c.noise_text, f"{c.kappa:g}"]
            + [f"{100 * np.mean(R[c][lab]['ess']):.2g} %" for lab in filters]
            + [" / ".join(f"{int(R[c][lab]['lost'].sum())}/{len(R[c][lab]['lost'])}" for lab in filters)]
            for c in grid
        ],
    )


def _table_cost(R: dict, grid) -> str:
    """µs per step of each filter, and GPF / MMPF, in every grid cell."""
    return render.table(
        ["sensors", "κ", *[f"{lab} µs/step" for lab in MAIN], "GPF/MMPF"],
        [
            [render.anchor_tag("#e-cost") * (c == grid[0]) + c.noise_text, f"{c.kappa:g}"]
            + [f"{R[c][lab]['row']['us_per_step']:.0f}" for lab in MAIN]
            + [f"{R[c]['GPF']['row']['us_per_step'] / R[c]['MMPF']['row']['us_per_step']:.2f}"]
            for c in grid
        ],
    )


def tables(R: dict, T: dict, p: dict) -> dict:
    """The evidence tables of the template (each a Markdown table; anchors on the claims' rows)."""
    grid = p["grid"]
    return {
        "best": _table_best(R, T, grid),
        "grid": _table_order(R, grid),
        "maneuvers": _table_maneuvers(R, grid),
        "profiles": render.table(
            ["κ", "profile", *[f"{ch}: GPF − MMPF / MMPF − EKF" for ch in CH]],
            [[f"{c.kappa:g}", c.profile] + [order(R[c], ch) for ch in CH] for c in p["profiles"]],
        ),
        "ablation": _table_ablation(R, p["ablation"]),
        "lead": _table_lead(R, grid),
        "ess": _table_ess(R, grid),
        "cost": _table_cost(R, grid),
    }


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    sw, p = Stopwatch(), plan(runs, quick)
    doc = Path(doc) if doc else Path("docs/reproduction/000.md")
    workers, R, T, commands = pool_workers(), {}, {}, {}
    args = [(c, labs, n, seed + s, p["duration"]) for c, labs, n, s in p["jobs"]]
    labels = [f"{a[0].name}: {', '.join(a[1])} ({a[2]} runs, seed {a[3]})" for a in args]
    with pool(workers) as ex:
        for _, out in run_longest_first(compute, args, [len(a[1]) * a[2] for a in args], labels, ex, quiet):
            (T if out["seed"] != seed else R).setdefault(out["cell"], {}).update(out["filters"])
            commands.setdefault((out["cell"], out["seed"]), []).append(out["command"])
    cmd = (
        "replay reproduce 000"
        + " --quick" * quick
        + (f" --runs {runs}" if runs else "")
        + (f" --seed {seed}" if seed else "")
    )
    ev = evidence(R, T, p)
    fields = {
        **{f"table_{k}": v for k, v in tables(R, T, p).items()},
        "command": cmd,
        "jobs": len(args),
        "workers": workers,
        "seed": seed,
        "tune_seed": seed + 1,
        "runs": p["runs"],
        "tune_runs": p["tune_runs"],
        "profile_runs": p["profile_runs"],
        "generated": ", ".join(f"{g:.3g}" for g in GENERATED_RMS),
        "rho": ", ".join(f"{g / r:.3g}" for g, r in zip(GENERATED_RMS, R_STD)),
        "matched": ", ".join(f"{g:.3g}²" for g in GENERATED_RMS),
        "units": ", ".join(UNITS.values()),
        "every_cell": "\n\n".join(
            f"### {c.name}{', tuning seed' * (s != seed)}\n\n"
            + result_rows(
                [R_or[c][lab]["row"] for lab in R_or[c]], ("depth_rmse", "speed_rmse", "pitch_rmse"), list(R_or[c]), 4
            )
            + "\n\n"
            + "  \n".join(f"`{x}`" for x in sorted(commands[(c, s)]))
            for R_or, s in ((R, seed), (T, seed + 1))
            for c in R_or
        ),
    }
    verdicts = decide([Claim(cid, w, pp, rule, EVIDENCE[cid]) for cid, w, pp, rule in CLAIMS], ev, seed)
    fields["relabelled"] = render.table(
        ["claim", "before", "now", "the number behind it"],
        [[v.claim.words, OLD[v.claim.id], v.label, render.found(v)] for v in verdicts],
    )
    fields["ess_paper"] = " ".join(
        f"{c.name}: mean ESS/N "
        + ", ".join(f"{lab} {100 * np.mean(R[c][lab]['ess']):.2g} %" for lab in ("GPF", "MMPF", "PF"))
        + "."
        for c in (PAPER, MISMATCH)
    )
    text = render.render("000", fields, verdicts) + footer(cmd, sw.seconds)
    write_document(doc, text)
    if not quiet:
        print(text)
        print(f"wrote {doc}", file=sys.stderr)
    return R, T
