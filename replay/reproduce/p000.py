"""``replay reproduce 000``: GPF vs MMPF vs EKF on synthetic lake-trial logs (paper 000), as data + a template.

``replay/papers/000.toml`` declares the cells (:class:`Cell`), filters, GPF variants, tuning seed, table heads,
the claims with their rules and the paired comparisons they name (its comments say how; :func:`experiment`
checks every key). :func:`compute` runs a cell through :func:`replay.run.evaluation.evaluate` (the pipeline of
``replay eval``); :func:`evidence` fills the comparisons, :func:`replay.reproduce.rules.decide` decides, and
:func:`tables` fills the prose ``replay/papers/000.md``. A filter variant, cell, grid value, claim or paired
comparison in named cells is a TOML edit; a new kind of statistic or table is code.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, replace

import numpy as np

from replay.campaign.longest import pool, run_longest_first
from replay.campaign.longest import workers as pool_workers
from replay.models.depth import R_FIXED, paper_Q
from replay.run.evaluation import evaluate
from replay.run.manifest import command_line
from replay.run.pipeline import plain
from replay.scoring import scorer
from replay.sim.lake_depth import base_for_rms, make_frame
from replay.util.portable import write_document

from . import render, spec
from .render import anchor_tag, fmt, pm, table
from .rules import Comparison, decide, per_run
from .tables import Stopwatch, footer, result_rows

RUNS, STATS = ("experiment", "quick"), {"rmse", "man", "level", "ratio"}
SCHEMA = {  # each kind of TOML entry -> its keys ("?": optional)
    "file": "experiment quick filters tables evidence claim",
    "experiment": "dataset task channels particles runs profile_runs tune_runs tune_seed grid profiles "
    "ablation_cells key_cells",
    "quick": "runs? duration? grid? profiles? ablation_cells?",
    **{"grid": "noises kappas", "profiles": "kappas seeds", "cell": "kappa noise?"},
    **{"filters": "main oracle ablation", "filter": "filter params?"},
    "tables": "best grid maneuvers profiles ablation lead ess cost relabelled",
    "evidence": "key cells pairs name of? kappa_below?",
}


def experiment(x: dict) -> dict:
    """``x`` if every entry has the keys of its kind in :data:`SCHEMA` (claims: :func:`spec.claims`), else a
    ``ValueError`` naming the file and the entry."""
    todo = [("file", x, "the top level"), *((k, x.get(k, {}), f"[{k}]") for k in ("filters", "tables", *RUNS))]
    todo += [("filter", e, f"[filters.{k}] {lab!r}") for k, t in x.get("filters", {}).items() for lab, e in t.items()]
    todo += [("evidence", e, f"[[evidence]] {e.get('key')!r}") for e in x.get("evidence", [])]
    for n, t in ((n, x.get(n, {})) for n in RUNS):
        todo += [(k, t[k], f"[{n}] {k}") for k in ("grid", "profiles") if k in t]
        todo += [
            ("cell", c, f"[{n}] cell {c}") for c in [*t.get("ablation_cells", []), *t.get("key_cells", {}).values()]
        ]
    for kind, t, entry in todo:
        spec.check(t, SCHEMA[kind], f"000.toml: {entry}")
    labels, cells = {lab for t in x["filters"].values() for lab in t}, {"ablation", *x["experiment"]["key_cells"]}
    for e in x["evidence"]:  # the names an [[evidence]] entry uses: cells, filter labels, the statistic
        bad = (
            set(e["cells"]) - cells | {lab for ab in e["pairs"] for lab in ab} - labels | {e.get("of", "rmse")} - STATS
        )
        if bad:
            raise ValueError(f"000.toml: [[evidence]] {e['key']!r}: unknown name(s) {sorted(bad)}")
    return x


X = experiment(spec.load("000"))
CLAIMS, EXP = spec.claims(X, "000.toml"), X["experiment"]
CH, N, R_STD, Q_DIAG = tuple(EXP["channels"]), EXP["particles"], np.sqrt(np.diag(R_FIXED)), np.diag(paper_Q()[0])
BASE = next(p.default for p in make_frame.PARAMS if p.name == "base_sigma")  # sim/lake-depth's sensors
GENERATED_RMS = tuple(float(b) / f for b, f in zip(BASE, base_for_rms((1.0, 1.0, 1.0))))  # their RMS over 90 s
tidy = lambda x: float(f"{float(x):.10g}")  # a short decimal for commands: 0.006, not 0.006000000000000001
MATCHED_R = [tidy(g * g) for g in GENERATED_RMS]  # the generated sensors' mean square noise (an oracle's R)
_params = lambda e: {k: MATCHED_R if v == "matched" else v for k, v in e.get("params", {}).items()}
MAIN, ORACLE, ABLATIONS = (
    {k: (e["filter"], _params(e)) for k, e in X["filters"][t].items()} for t in SCHEMA["filters"].split()
)
VARIANTS, OTHERS = {**MAIN, **ORACLE, **ABLATIONS}, tuple(MAIN)[1:]  # the baselines: every main filter but GPF
PFS, THREE = ("GPF", "MMPF", "PF"), ("GPF", "MMPF", "EKF")
_each = lambda h: CH if "{ch}" in h else MAIN if "{main}" in h else [""]  # [tables]: {ch}, {main} columns
HEADS = {k: [h.format(ch=x, main=x) for h in v for x in _each(h)] for k, v in X["tables"].items()}
SENSORS = {  # the template's numbers of sim/lake-depth's sensors as generated
    "generated": ", ".join(f"{g:.3g}" for g in GENERATED_RMS),
    "rho": ", ".join(f"{g / r:.3g}" for g, r in zip(GENERATED_RMS, R_STD)),
    "matched": ", ".join(f"{g:.3g}²" for g in GENERATED_RMS),
    "units": ", ".join(EXP["channels"].values()),
}


@dataclass(frozen=True)
class Cell:
    """Sensors at ``noise`` × the fixed R's std (None: as generated), Q = ``kappa`` × the paper's, ``profile`` seed.
    Cells of one sensor level draw the same noise, so its filters and cells are paired run by run."""

    noise: float | None
    kappa: float
    profile: int | None = None  # None: the fixed schedule

    @classmethod
    def of(cls, noise="generated", kappa=1.0, profile=None) -> Cell:  # from the TOML's values
        return cls(None if noise == "generated" else float(noise), float(kappa), profile)

    noise_text = property(lambda c: "as generated" if c.noise is None else f"{c.noise:g} R")
    where = property(lambda c: "fixed profile" if c.profile is None else f"profile {c.profile}")
    name = property(lambda c: f"sensors {c.noise_text}, κ = {c.kappa:g}, {c.where}")


KEY = {name: Cell.of(**c) for name, c in EXP["key_cells"].items()}
cmp = lambda name, fa, fb, ch, key="rmse": Comparison(name, fa[key][ch], fb[key][ch], fa["lost"], fb["lost"])


def compute(job) -> dict:
    """``(cell, labels, runs, seed, duration)`` -> per filter (the labels' filters differ): the leaderboard row, per-run
    RMSE per channel (diverged +inf) and lost flags, the same over the maneuvers and the level runs, mean ESS / N."""
    cell, labels, runs, seed, duration = job
    data = {} if cell.noise is None else {"noise_rms": [tidy(cell.noise * s) for s in R_STD]}
    data |= {} if cell.profile is None else {"profile_seed": int(cell.profile)}
    data |= {} if duration is None else {"duration": float(duration)}
    task = {} if cell.kappa == 1.0 else {"Q": [tidy(cell.kappa * q) for q in Q_DIAG]}
    f = dict(VARIANTS[lab] for lab in labels)
    kw = dict(runs=runs, seed=seed, dataset_params=data, task_params=task, filter_params=f)
    ev = evaluate(EXP["dataset"], task=EXP["task"], filters=list(f), **kw)
    out = {"cell": cell, "seed": seed, "command": command_line(ev.config), "t": np.asarray(ev.t, float), "filters": {}}
    out["maneuvers"] = plain(ev.frame_meta["maneuvers"])
    for lab, res, row in zip(labels, ev.results, ev.rows):
        div, seg = np.array([bool(m["diverged"]) for m in res.runs]), {"man": [], "level": []}
        for rec in res.records:  # the reference restricted to the maneuvers (+1.5 s settling), and to the rest
            p, t = rec["problem"], np.asarray(rec["problem"].t, float)
            man = np.any([(t >= a) & (t < b) for a, b, _ in p.frame_meta["maneuvers"]], axis=0)
            for k, keep in (("man", man), ("level", ~man)):
                seg[k].append(scorer.score_run(replace(p, truth_valid=p.truth_valid & keep), rec["estimates"]))
        f = {k: {ch: np.where(div, np.inf, [m[f"{ch}_rmse"] for m in v]) for ch in CH} for k, v in seg.items()}
        with np.errstate(all="ignore"):
            f["ratio"] = {ch: f["man"][ch] / f["level"][ch] for ch in CH}
        f |= {"row": plain(row), "rmse": {ch: per_run(res, f"{ch}_rmse")[0] for ch in CH}}
        ess = np.array([e.info.get("mean_ess", np.nan) / N for e in res.estimates])
        out["filters"][lab] = f | {"lost": per_run(res, "depth_rmse")[1], "ess": ess}
    return out


def plan(runs=None, quick=False) -> dict:
    """Runs, cells and the evaluation jobs ``(cell, labels, runs, seed offset)`` of ``[experiment]`` or ``[quick]``."""
    q = {**EXP, "duration": None, **(X["quick"] if quick else {})}
    p = {"runs": runs or q["runs"], "duration": q["duration"], "kappas": q["grid"]["kappas"]}
    p |= {k: max(2, round(p["runs"] * EXP[k] / EXP["runs"])) for k in ("profile_runs", "tune_runs")}
    p["noises"] = [Cell.of(n).noise for n in q["grid"]["noises"]]
    p["grid"] = [Cell.of(n, k) for n in q["grid"]["noises"] for k in p["kappas"]]
    p["profiles"] = [Cell.of(kappa=k, profile=s) for k in q["profiles"]["kappas"] for s in q["profiles"]["seeds"]]
    p["ablation"] = [Cell.of(**c) for c in q["ablation_cells"]]
    both = ((p["runs"], 0), (p["tune_runs"], EXP["tune_seed"]))
    jobs = [(c, tuple(MAIN), n, s) for n, s in both for c in p["grid"]]
    jobs += [(c, tuple(ORACLE), n, s) for c in p["grid"] if c.noise is None for n, s in both]
    jobs += [(c, tuple(MAIN), p["profile_runs"], 0) for c in p["profiles"]]
    return p | {"jobs": jobs + [(c, (lab,), p["runs"], 0) for c in p["ablation"] for lab in ABLATIONS]}


def lead(res: dict, ch: str) -> dict:
    """Per-run lead of GPF over the baseline with the lowest mean RMSE in the cell (``best``): 1 − GPF / best."""
    best = min(OTHERS, key=lambda lab: np.mean(res[lab]["rmse"][ch]))
    with np.errstate(all="ignore"):
        v = 1 - res["GPF"]["rmse"][ch] / res[best]["rmse"][ch]
    return {"lead": {ch: v}, "lost": res["GPF"]["lost"] | res[best]["lost"], "best": best}


def tuned(T: dict, R: dict, grid) -> dict:
    """(label, channel) -> (cell, variant, its results in R): the lowest mean RMSE on the tuning seed's ``T``."""
    out = {}
    for lab, ch in [(lab, ch) for lab in MAIN for ch in CH]:
        options = [(c, v) for c in grid if c.noise is None for v in (lab, f"{lab}, R matched") if v in T[c]]
        c, v = min(options, key=lambda o: np.mean(T[o[0]][o[1]]["rmse"][ch]))
        out[(lab, ch)] = (c, v, R[c][v])
    return out


def evidence(R: dict, T: dict, p: dict) -> dict:
    """The comparisons the rules name: each ``[[evidence]]`` (cells × channels × pairs), then best (each filter tuned),
    cost (µs per step over the grid), lead-q (first vs last κ per sensor level), lead-r (1 R vs lowest per κ)."""
    ev, at, cell = {}, tuned(T, R, p["grid"]), {(c.noise, c.kappa): R[c] for c in p["grid"]}
    for e in X["evidence"]:
        cells = [(n, c) for n in e["cells"] for c in (p["ablation"] if n == "ablation" else [KEY[n]])]
        for n, c, ch, (a, b) in [(n, c, ch, ab) for n, c in cells for ch in CH for ab in e["pairs"]]:
            name, key = (
                e["name"].format(sensors=c.noise_text, kappa=c.kappa, ch=ch, a=a, b=b),
                e["key"].format(tag=n, ch=ch),
            )
            if c.kappa < e.get("kappa_below", np.inf):
                ev.setdefault(key, []).append(cmp(name, R[c][a], R[c][b], ch, e.get("of", "rmse")))
    ev["best"] = [cmp(f"{ch}: GPF − {lab}", at[("GPF", ch)][2], at[(lab, ch)][2], ch) for ch in CH for lab in OTHERS]
    us = ([R[c][lab]["row"]["us_per_step"] for c in p["grid"]] for lab in ("GPF", "MMPF"))
    ev["cost"] = [Comparison("GPF − MMPF, µs per step over the grid cells", *us)]
    lo, k = [n for n in p["noises"] if n is not None], p["kappas"]
    rows = [("lead-q", f"sensors {Cell(n, 1).noise_text}", (n, k[0]), (n, k[-1])) for n in p["noises"]]
    for key, name, x, y in rows + [("lead-r", f"κ = {x:g}", (max(lo), x), (min(lo), x)) for x in k]:
        ev.setdefault(key, []).extend(
            cmp(f"{name}, {ch}", lead(cell[x], ch), lead(cell[y], ch), ch, "lead") for ch in CH
        )
    return ev


def tables(R: dict, T: dict, p: dict) -> dict:
    """The evidence tables of the template (anchors on the claims' rows); differences paired, mean ± 95 %."""
    g, abl, at, mark = p["grid"], p["ablation"], tuned(T, R, p["grid"]), lambda a, here: anchor_tag(a) if here else ""
    rm = lambda lab, ch: at[(lab, ch)][2]["rmse"][ch]  # a filter's per-run RMSE at its tuned setting
    d = lambda c, x, y, ch: pm(R[c][x]["rmse"][ch], R[c][y]["rmse"][ch])
    order = lambda c: [f"{d(c, 'GPF', 'MMPF', ch)} / {d(c, 'MMPF', 'EKF', ch)}" for ch in CH]
    m = lambda c, k, ch, f=fmt: " / ".join(f(np.mean(R[c][lab][k][ch])) for lab in THREE)
    us = lambda c, lab: R[c][lab]["row"]["us_per_step"]
    by_cell = lambda k, cols, a="", first=None: table(
        HEADS[k], [[mark(a, c == first) + c.noise_text, f"{c.kappa:g}", *cols(c)] for c in g]
    )
    other = {ch: min(OTHERS, key=lambda lab: np.mean(rm(lab, ch))) for ch in CH}
    tune = lambda lab, ch: f"κ = {at[(lab, ch)][0].kappa:g}{at[(lab, ch)][1][len(lab) :]}"
    gap = lambda ch: f"{pm(rm('GPF', ch), rm(other[ch], ch))} ({other[ch]})"  # GPF − the best other
    best = [[ch, *(f"{fmt(np.mean(rm(lab, ch)))} ({tune(lab, ch)})" for lab in MAIN), gap(ch)] for ch in CH]
    man = [
        [c.name, ch, m(c, "man", ch), m(c, "level", ch), m(c, "ratio", ch, "{:.2f}".format)]
        for c in KEY.values()
        if c in g
        for ch in CH
    ]
    abl = [[c.name, lab, *(d(c, lab, "GPF", ch) for ch in CH)] for c in abl for lab in ABLATIONS]
    lost = lambda c: " / ".join(f"{int(R[c][lab]['lost'].sum())}/{len(R[c][lab]['lost'])}" for lab in PFS)
    grows = lambda c: [f"{100 * np.nanmean(lead(R[c], ch)['lead'][ch]):+.0f} % ({lead(R[c], ch)['best']})" for ch in CH]
    return {
        "best": table(HEADS["best"], [[mark("#e-best", i == 0) + r[0], *r[1:]] for i, r in enumerate(best)]),
        "grid": by_cell("grid", order, "#e-order", KEY["paper"]),
        "maneuvers": table(
            HEADS["maneuvers"],
            [[mark("#e-man", (c, ch) == (KEY["paper"].name, CH[0])) + c, ch, *r] for c, ch, *r in man],
        ),
        "profiles": table(HEADS["profiles"], [[f"{c.kappa:g}", c.profile, *order(c)] for c in p["profiles"]]),
        "ablation": table(HEADS["ablation"], [[mark("#e-ablation", i == 0) + r[0], *r[1:]] for i, r in enumerate(abl)]),
        "lead": by_cell("lead", grows, "#e-lead", g[0]),
        "ess": by_cell("ess", lambda c: [f"{100 * np.mean(R[c][lab]['ess']):.2g} %" for lab in PFS] + [lost(c)]),
        "cost": by_cell(
            "cost",
            lambda c: [f"{us(c, lab):.0f}" for lab in MAIN] + [f"{us(c, 'GPF') / us(c, 'MMPF'):.2f}"],
            "#e-cost",
            g[0],
        ),
    }


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Compute every job of :func:`plan` in worker processes, decide the claims, write the document."""
    sw, p, workers, tune = Stopwatch(), plan(runs, quick), pool_workers(), seed + EXP["tune_seed"]
    args = [(c, labs, n, seed + s, p["duration"]) for c, labs, n, s in p["jobs"]]
    labels = [f"{a[0].name}: {', '.join(a[1])} ({a[2]} runs, seed {a[3]})" for a in args]
    with pool(workers) as ex:
        outs = dict(run_longest_first(compute, args, [len(a[1]) * a[2] for a in args], labels, ex, quiet))
    R, T, commands = {}, {}, {}
    for out in (outs[i] for i in range(len(args))):  # the plan's order, not the order the evaluations finished
        (T if out["seed"] == tune else R).setdefault(out["cell"], {}).update(out["filters"])
        commands.setdefault((out["cell"], out["seed"]), []).append(out["command"])
    cmd = "replay reproduce 000" + " --quick" * quick + f" --runs {runs}" * bool(runs) + f" --seed {seed}" * bool(seed)
    verdicts, old = decide(CLAIMS, evidence(R, T, p), seed), spec.old_labels(X)
    rows = lambda res, c: result_rows([f["row"] for f in res[c].values()], [f"{ch}_rmse" for ch in CH], list(res[c]), 4)
    cmds = lambda c, s: "  \n".join(f"`{x}`" for x in sorted(commands[(c, s)]))
    cells = [
        f"### {c.name}{', tuning seed' * (s == tune)}\n\n{rows(res, c)}\n\n{cmds(c, s)}"
        for res, s in ((R, seed), (T, tune))
        for c in res
    ]
    ess = lambda c: ", ".join(f"{lab} {100 * np.mean(R[c][lab]['ess']):.2g} %" for lab in PFS)
    relabel = [[v.claim.words, old[v.claim.id], v.label, render.found(v)] for v in verdicts]
    fields = {f"table_{k}": v for k, v in tables(R, T, p).items()} | SENSORS
    fields |= {k: p[k] for k in ("runs", "tune_runs", "profile_runs")} | {"every_cell": "\n\n".join(cells)}
    fields |= dict(command=cmd, jobs=len(args), workers=workers, seed=seed, tune_seed=tune)
    fields["relabelled"] = table(HEADS["relabelled"], relabel)
    fields["ess_paper"] = " ".join(f"{c.name}: mean ESS/N {ess(c)}." for c in KEY.values())
    text = render.render("000", fields, verdicts) + footer(cmd, sw.seconds)
    doc = write_document(doc or "docs/reproduction/000.md", text)
    if not quiet:
        print(text)
        print(f"wrote {doc}", file=sys.stderr)
    return R, T
