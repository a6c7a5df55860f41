"""``replay reproduce 000``: GPF vs MMPF vs EKF on synthetic lake-trial logs (paper 000), as data + a template.

The experiments (:mod:`replay.reproduce.p000_cells`): a grid of sensor level × κ on the fixed
schedule, random maneuver schedules, GPF ablations, every filter (and the baselines with R
matched to the sensors) on a **tuning seed** (master seed + 1) to pick each filter's best
setting, then compared on the verdict seed. The claims and their rules are :data:`CLAIMS`,
declared before the run; :func:`evidence` fills the comparisons the rules name; the verdicts
come from :func:`replay.reproduce.rules.decide`; the prose is ``templates/000.md``.
``quick``: 20 s logs, 2 runs, a 3 × 2 grid, 2 profiles (a smoke check of the path).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from . import render
from .render import fmt, pm
from .p000_cells import ABLATIONS, CH, GENERATED_RMS, MAIN, ORACLE, R_STD, UNITS, Cell, compute
from .pool import pool, run_longest_first, workers as pool_workers
from .rules import Claim, Comparison, Rule, decide
from .verdict import Stopwatch, footer, result_rows, write_document

NOISES, KAPPAS, PROFILES, PROFILE_KAPPAS = (None, 0.03, 0.3, 1.0), (1.0, 1e-2, 1e-4), (1, 2, 3, 4, 5, 6), (1.0, 1e-4)
PAPER, MISMATCH = Cell(None, 1.0), Cell(None, 1e-4)
ABLATION_CELLS = (PAPER, MISMATCH, Cell(1.0, 1e-4))
RUNS, PROFILE_RUNS, TUNE_RUNS = 8, 5, 8  # per grid/ablation cell, per profile cell, per tuning cell
QUICK = {"runs": 2, "duration": 20.0, "noises": (None, 0.3, 1.0), "kappas": (1.0, 1e-4), "profiles": (1, 2),
         "profile_kappas": (1e-4,), "ablation_cells": (PAPER, MISMATCH)}
OTHERS = ("MMPF", "EKF", "UKF", "PF")
MISMATCH_TEXT = "κ = 1e-4 (Q too small for the maneuvers: the case GPF is designed for), sensors as generated"
ORDER = "per-run {} RMSE: GPF − MMPF and MMPF − EKF"
CLAIMS = [  # (id, the paper's words, the paper's number, the rule): declared before any run
    ("best", "GPF is more accurate than the baselines, each at its best Q and R (a referee's condition)",
     "GPF most accurate (Fig. 4–6)", Rule("best", "sensors as generated; each filter's κ (and R) tuned on the "
                                          "tuning seed", "per-run RMSE: GPF − each baseline, 3 channels")),
    *[(ch, f"{ch} RMSE: GPF < MMPF < EKF (Fig. {4 + i})", "GPF < MMPF < EKF (figures only)",
       Rule(f"{ch}@paper", "the paper's setting (sensors as generated, κ = 1)", ORDER.format(ch),
            condition=f"{ch}@mismatch", condition_text=MISMATCH_TEXT, mechanism=f"{ch}@fixedR",
            mechanism_text=f"GPF with the fixed R beats GPF in {ch} at the paper's setting (its wavelet R "
                           "follows the measurements)")) for i, ch in enumerate(CH)],
    ("worst", "the EKF is worst while the AUV maneuvers (§3, Fig. 4–6)", "EKF worst during maneuvers",
     Rule("worst@paper", "the paper's setting, maneuver segments", "per-run RMSE over the maneuvers: GPF − EKF, "
          "MMPF − EKF, 3 channels", condition="worst@mismatch", condition_text=MISMATCH_TEXT)),
    ("degrades", "the EKF degrades most when the AUV maneuvers", "EKF degrades most (digest)",
     Rule("degrades@paper", "the paper's setting", "per-run maneuver/level RMSE ratio: GPF − EKF, MMPF − EKF, "
          "3 channels", condition="degrades@mismatch", condition_text=MISMATCH_TEXT)),
    ("cost", "GPF needs less computation than MMPF (§3)", "less (no numbers)",
     Rule("cost", "every grid cell", "filter time per step: GPF − MMPF, paired over the cells", test="t")),
    ("lead-q", "GPF's lead grows as the motion model gets worse (§3)", "grows",
     Rule("lead-q", "each (sensor level, channel): κ = 1 against the smallest κ", "per-run lead 1 − GPF/best "
          "baseline: at κ = 1 − at the smallest κ", need="majority")),
    ("lead-r", "GPF's lead grows as the fixed R gets worse (sensors further below R, §3)", "grows",
     Rule("lead-r", "each (κ, channel): sensors at 1 R against the lowest level", "per-run lead: at 1 R − at the "
          "lowest sensor level", need="majority")),
    ("grey", "grey particles keep GPF on track when the model mismatches the maneuvers (§2.4)", "yes (argued)",
     Rule("grey", "the ablation cells with κ < 1", "per-run RMSE: GPF − GPF without grey particles, 3 channels")),
    ("wavelet", "the wavelet estimate of R improves GPF (§2.3)", "yes (argued)",
     Rule("wavelet", "every ablation cell", "per-run RMSE: GPF − GPF with the fixed R, 3 channels")),
]
OLD = {"depth": "deviation explained (holds in 1/12 cells)", "speed": "deviation explained (2/12 cells)",
       "pitch": "deviation explained (6/12 cells)", "worst": "deviation explained (3/12 cells)",
       "degrades": "not reproduced (0/12 cells)", "cost": "not reproduced (GPF/MMPF 1.07)",
       "lead-q": "not reproduced (9/12 pairs, rule 12/12)", "lead-r": "not reproduced (6/9 pairs, rule 9/9)",
       "grey": "not reproduced (3/6)", "wavelet": "not reproduced (3/9)", "best": "(new row)"}
EVIDENCE = {"best": "#e-best", "depth": "#e-order", "speed": "#e-order", "pitch": "#e-order", "worst": "#e-man",
            "degrades": "#e-man", "cost": "#e-cost", "lead-q": "#e-lead", "lead-r": "#e-lead",
            "grey": "#e-ablation", "wavelet": "#e-ablation"}


def plan(runs=None, quick=False) -> dict:
    q = QUICK if quick else {}
    runs = runs or q.get("runs", RUNS)
    p = {"runs": runs, "profile_runs": max(2, round(runs * PROFILE_RUNS / RUNS)), "duration": q.get("duration"),
         "tune_runs": max(2, round(runs * TUNE_RUNS / RUNS)), "noises": q.get("noises", NOISES),
         "kappas": q.get("kappas", KAPPAS), "ablation": list(q.get("ablation_cells", ABLATION_CELLS))}
    p["grid"] = [Cell(n, k) for n in p["noises"] for k in p["kappas"]]
    p["profiles"] = [Cell(None, k, s) for k in q.get("profile_kappas", PROFILE_KAPPAS)
                     for s in q.get("profiles", PROFILES)]
    oracle = [c for c in p["grid"] if c.noise is None]
    p["jobs"] = ([(c, tuple(MAIN), runs, 0) for c in p["grid"]] + [(c, tuple(MAIN), p["tune_runs"], 1)
                                                                     for c in p["grid"]]
                 + [(c, tuple(ORACLE), n, s) for c in oracle for n, s in ((runs, 0), (p["tune_runs"], 1))]
                 + [(c, tuple(MAIN), p["profile_runs"], 0) for c in p["profiles"]]
                 + [(c, (lab,), runs, 0) for c in p["ablation"] for lab in ABLATIONS])
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
        return {"v": {ch: 1 - res["GPF"]["rmse"][ch] / res[best]["rmse"][ch]},
                "lost": res["GPF"]["lost"] | res[best]["lost"], "best": best}


def tuned(T: dict, grid, noise) -> dict:
    """(label, channel) -> the setting (cell, variant label) with the lowest mean RMSE on the tuning seed."""
    out = {}
    for lab in MAIN:
        options = [(c, v) for c in grid if c.noise == noise for v in (lab, f"{lab}, R matched") if v in T[c]]
        for ch in CH:
            out[(lab, ch)] = min(options, key=lambda o: _mean(T[o[0]][o[1]]["rmse"][ch]))
    return out


def evidence(R: dict, T: dict, p: dict) -> dict:
    """The comparisons every rule of :data:`CLAIMS` names (``R``: verdict seed, ``T``: tuning seed)."""
    ev, grid = {}, p["grid"]
    best = tuned(T, grid, None)
    ev["best"] = [cmp(f"{ch}: GPF − {lab}", R[best[("GPF", ch)][0]][best[("GPF", ch)][1]],
                      R[best[(lab, ch)][0]][best[(lab, ch)][1]], ch=ch) for ch in CH for lab in OTHERS]
    for cell, tag in ((PAPER, "paper"), (MISMATCH, "mismatch")):
        r = R[cell]
        for ch in CH:
            ev[f"{ch}@{tag}"] = [cmp(f"κ = {cell.kappa:g}: GPF − MMPF", r["GPF"], r["MMPF"], ch=ch),
                                 cmp(f"κ = {cell.kappa:g}: MMPF − EKF", r["MMPF"], r["EKF"], ch=ch)]
        ev[f"worst@{tag}"] = [cmp(f"κ = {cell.kappa:g}, {ch}: {lab} − EKF", r[lab], r["EKF"], "man", ch)
                              for ch in CH for lab in ("GPF", "MMPF")]
        ev[f"degrades@{tag}"] = [cmp(f"κ = {cell.kappa:g}, {ch}: {lab} − EKF", ratio(r[lab], ch), ratio(r["EKF"], ch),
                                     "r", ch) for ch in CH for lab in ("GPF", "MMPF")]
    for ch in CH:
        ev[f"{ch}@fixedR"] = [cmp(f"{ch}: GPF with the fixed R − GPF", R[PAPER]["GPF with the fixed R"],
                                  R[PAPER]["GPF"], ch=ch)]
    us = {lab: [R[c][lab]["row"]["us_per_step"] for c in grid] for lab in ("GPF", "MMPF")}
    ev["cost"] = [Comparison("GPF − MMPF, µs per step over the grid cells", us["GPF"], us["MMPF"])]
    noises, kappas = [n for n in p["noises"] if n is not None], p["kappas"]
    cell = {(c.noise, c.kappa): R[c] for c in grid}
    ev["lead-q"] = [cmp(f"sensors {Cell(n, 1).noise_text}, {ch}", lead(cell[(n, kappas[0])], ch),
                        lead(cell[(n, kappas[-1])], ch), "v", ch) for n in p["noises"] for ch in CH]
    ev["lead-r"] = [cmp(f"κ = {k:g}, {ch}", lead(cell[(max(noises), k)], ch), lead(cell[(min(noises), k)], ch), "v", ch)
                    for k in kappas for ch in CH]
    name = lambda c, ch: f"sensors {c.noise_text}, κ = {c.kappa:g}, {ch}"
    ev["grey"] = [cmp(name(c, ch), R[c]["GPF"], R[c]["GPF without grey particles"], ch=ch)
                  for c in p["ablation"] if c.kappa < 1 for ch in CH]
    ev["wavelet"] = [cmp(name(c, ch), R[c]["GPF"], R[c]["GPF with the fixed R"], ch=ch)
                     for c in p["ablation"] for ch in CH]
    return ev


def tables(R: dict, T: dict, p: dict) -> dict:
    """The evidence tables of the template (each a Markdown table; anchors on the claims' rows)."""
    t, grid, tag = {}, p["grid"], render.anchor_tag
    best = tuned(T, grid, None)
    at = {(lab, ch): R[best[(lab, ch)][0]][best[(lab, ch)][1]]["rmse"][ch] for lab in MAIN for ch in CH}
    other = {ch: min(OTHERS, key=lambda lab: _mean(at[(lab, ch)])) for ch in CH}
    t["best"] = render.table(["channel", *MAIN, "GPF − the best other (paired)"], [
        [tag("#e-best") * (ch == "depth") + ch]
        + [f"{fmt(_mean(at[(lab, ch)]))} (κ = {best[(lab, ch)][0].kappa:g}"
           f"{', R matched' * ('R m' in best[(lab, ch)][1])})" for lab in MAIN]
        + [f"{pm(at[('GPF', ch)], at[(other[ch], ch)])} ({other[ch]})"] for ch in CH])
    t["grid"] = render.table(["sensors", "κ", *[f"{ch}: GPF − MMPF / MMPF − EKF" for ch in CH]], [
        [tag("#e-order") * (c == PAPER) + c.noise_text, f"{c.kappa:g}"]
        + [order(R[c], ch) for ch in CH] for c in grid])
    key = [c for c in (PAPER, MISMATCH) if c in grid]
    t["maneuvers"] = render.table(["cell", "channel", "maneuvers GPF / MMPF / EKF", "level GPF / MMPF / EKF",
                                   "ratio GPF / MMPF / EKF"], [
        [tag("#e-man") * (c == PAPER and ch == "depth") + c.name, ch]
        + [" / ".join(fmt(_mean(R[c][lab][k][ch])) for lab in ("GPF", "MMPF", "EKF")) for k in ("man", "level")]
        + [" / ".join(f"{np.mean(ratio(R[c][lab], ch)['r'][ch]):.2f}" for lab in ("GPF", "MMPF", "EKF"))]
        for c in key for ch in CH])
    t["profiles"] = render.table(["κ", "profile", *[f"{ch}: GPF − MMPF / MMPF − EKF" for ch in CH]], [
        [f"{c.kappa:g}", c.profile] + [order(R[c], ch) for ch in CH] for c in p["profiles"]])
    t["ablation"] = render.table(["cell", "variant", *[f"{ch}: variant − GPF" for ch in CH]], [
        [tag("#e-ablation") * (c == p["ablation"][0] and lab == "GPF without grey particles") + c.name, lab]
        + [pm(R[c][lab]["rmse"][ch], R[c]["GPF"]["rmse"][ch]) for ch in CH]
        for c in p["ablation"] for lab in ABLATIONS])
    t["lead"] = render.table(["sensors", "κ", *CH], [
        [tag("#e-lead") * (c == grid[0]) + c.noise_text, f"{c.kappa:g}"]
        + [f"{100 * np.nanmean(lead(R[c], ch)['v'][ch]):+.0f} % ({lead(R[c], ch)['best']})" for ch in CH]
        for c in grid])
    t["ess"] = render.table(["sensors", "κ", "ESS/N GPF", "ESS/N MMPF", "ESS/N PF", "lost GPF / MMPF / PF"], [
        [c.noise_text, f"{c.kappa:g}"] + [f"{100 * np.mean(R[c][lab]['ess']):.2g} %" for lab in ("GPF", "MMPF", "PF")]
        + [" / ".join(f"{int(R[c][lab]['lost'].sum())}/{len(R[c][lab]['lost'])}" for lab in ("GPF", "MMPF", "PF"))]
        for c in grid])
    t["cost"] = render.table(["sensors", "κ", *[f"{lab} µs/step" for lab in MAIN], "GPF/MMPF"], [
        [tag("#e-cost") * (c == grid[0]) + c.noise_text, f"{c.kappa:g}"]
        + [f"{R[c][lab]['row']['us_per_step']:.0f}" for lab in MAIN]
        + [f"{R[c]['GPF']['row']['us_per_step'] / R[c]['MMPF']['row']['us_per_step']:.2f}"] for c in grid])
    return t


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
    cmd = "replay reproduce 000" + " --quick" * quick + (f" --runs {runs}" if runs else "") + (
        f" --seed {seed}" if seed else "")
    ev = evidence(R, T, p)
    fields = {**{f"table_{k}": v for k, v in tables(R, T, p).items()}, "command": cmd, "jobs": len(args),
              "workers": workers, "seed": seed, "tune_seed": seed + 1, "runs": p["runs"], "tune_runs": p["tune_runs"],
              "profile_runs": p["profile_runs"], "generated": ", ".join(f"{g:.3g}" for g in GENERATED_RMS),
              "rho": ", ".join(f"{g / r:.3g}" for g, r in zip(GENERATED_RMS, R_STD)),
              "matched": ", ".join(f"{g:.3g}²" for g in GENERATED_RMS), "units": ", ".join(UNITS.values()),
              "every_cell": "\n\n".join(
                  f"### {c.name}{', tuning seed' * (s != seed)}\n\n" + result_rows(
                      [R_or[c][lab]["row"] for lab in R_or[c]], ("depth_rmse", "speed_rmse", "pitch_rmse"),
                      list(R_or[c]), 4) + "\n\n" + "  \n".join(f"`{x}`" for x in sorted(commands[(c, s)]))
                  for R_or, s in ((R, seed), (T, seed + 1)) for c in R_or)}
    verdicts = decide([Claim(cid, w, pp, rule, EVIDENCE[cid]) for cid, w, pp, rule in CLAIMS], ev, seed)
    fields["relabelled"] = render.table(["claim", "before", "now", "the number behind it"], [
        [v.claim.words, OLD[v.claim.id], v.label, render.found(v)] for v in verdicts])
    fields["ess_paper"] = " ".join(
        f"{c.name}: mean ESS/N " + ", ".join(f"{lab} {100 * np.mean(R[c][lab]['ess']):.2g} %"
                                              for lab in ("GPF", "MMPF", "PF")) + "." for c in (PAPER, MISMATCH))
    text = render.render("000", fields, verdicts) + footer(cmd, sw.seconds)
    write_document(doc, text)
    if not quiet:
        print(text)
        print(f"wrote {doc}", file=sys.stderr)
    return R, T
