"""``replay reproduce 000``: GPF vs MMPF vs EKF on synthetic lake-trial logs (paper 000), as data + a template.

Everything declared is in ``replay/papers/000.toml`` (its header says what each table means; every
key is checked, :func:`experiment`): a grid of sensor level × κ on the fixed schedule, random maneuver
profiles, GPF ablations, every filter (and the baselines with R matched to the sensors) on a tuning
seed to pick each filter's best setting, then compared on the verdict seed; the claims with their
rules; the paired comparisons the rules name (``[[evidence]]``). A :class:`Cell` is one setting of
the generator and the task; :func:`compute` runs a cell through :func:`replay.run.evaluation.evaluate`
(the pipeline of ``replay eval``) and keeps per filter the leaderboard row, the per-run RMSE of each
channel (diverged +inf, lost flags), the same over the maneuvers and the level runs, and the particle
filters' mean ESS / N. :func:`evidence` fills the comparisons; :func:`replay.reproduce.rules.decide`
gives the verdicts; :func:`tables` the evidence tables of the prose ``replay/papers/000.md``.
An ablation, a cell, a grid value, a claim or a comparison of two filters in named cells is a TOML
edit (``[filters.ablation]``, ``[experiment]``, ``[[claim]]``, ``[[evidence]]``), not code.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from replay.models.depth import R_FIXED, paper_Q
from replay.run.evaluation import evaluate
from replay.run.manifest import command_line
from replay.run.pipeline import plain
from replay.scoring import scorer
from replay.sim.lake_depth import base_for_rms, make_frame

from . import render, spec
from .pool import pool, run_longest_first, workers as pool_workers
from .render import anchor_tag as tag, fmt, pm
from .rules import Comparison, decide, per_run
from .verdict import Stopwatch, footer, result_rows, write_document

SCHEMA = {  # each kind of TOML entry -> its keys ("?": optional)
    "file": "experiment quick filters evidence claim",
    "experiment": "dataset task channels particles runs profile_runs tune_runs tune_seed grid profiles ablation_cells "
    "key_cells",
    "quick": "runs? duration? grid? profiles? ablation_cells?",
    "grid": "noises kappas",
    "profiles": "kappas seeds",
    "cell": "kappa noise?",
    "filters": "main oracle ablation",
    "filter": "filter params?",
    "evidence": "key cells pairs name of? kappa_below?",
}


def check(table: dict, kind: str, entry: str) -> dict:
    """``table`` if its keys are those of ``SCHEMA[kind]``, else ``ValueError`` naming the file and the entry."""
    keys = SCHEMA[kind].split()
    unknown, missing = set(table) - {k.rstrip("?") for k in keys}, {k for k in keys if "?" not in k} - set(table)
    if unknown or missing:
        what = f"unknown key(s) {sorted(unknown)}" if unknown else f"missing {sorted(missing)}"
        raise ValueError(f"000.toml: {entry}: {what}")
    return table


def experiment(x: dict) -> dict:
    """The paper's TOML table ``x``, every entry checked (:data:`SCHEMA`); the claims by :func:`spec.claims`."""
    check(x, "file", "the top level")
    for name in ("experiment", "quick"):
        t = check(x[name], name, f"[{name}]")
        for key in ("grid", "profiles"):
            if key in t:
                check(t[key], key, f"[{name}] {key}")
        for c in [*t.get("ablation_cells", []), *t.get("key_cells", {}).values()]:
            check(c, "cell", f"[{name}] cell {c}")
    for kind, table in check(x["filters"], "filters", "[filters]").items():
        for label, e in table.items():
            check(e, "filter", f"[filters.{kind}] {label!r}")
    for e in x["evidence"]:
        check(e, "evidence", f"[[evidence]] {e.get('key')!r}")
    return x


X = experiment(spec.load("000"))
CLAIMS, EXP = spec.claims(X, "000.toml"), X["experiment"]
CH, N = tuple(EXP["channels"]), EXP["particles"]
R_STD, Q_DIAG = np.sqrt(np.diag(R_FIXED)), np.diag(paper_Q()[0])
BASE = next(p.default for p in make_frame.PARAMS if p.name == "base_sigma")  # sim/lake-depth's sensors
GENERATED_RMS = tuple(float(b) / f for b, f in zip(BASE, base_for_rms((1.0, 1.0, 1.0))))  # their RMS over 90 s


def tidy(x: float) -> float:  # a short decimal for commands: 0.006, not 0.006000000000000001
    return float(f"{float(x):.10g}")


def _variant(e: dict) -> tuple:  # (filter, params) of a [filters.*] entry; R = "matched": MATCHED_R
    return e["filter"], {k: MATCHED_R if v == "matched" else v for k, v in e.get("params", {}).items()}


MATCHED_R = [tidy(g * g) for g in GENERATED_RMS]  # the generated sensors' mean square noise (an oracle's R)
MAIN, ORACLE, ABLATIONS = (
    {lab: _variant(e) for lab, e in X["filters"][k].items()} for k in ("main", "oracle", "ablation")
)
VARIANTS, OTHERS, PFS = {**MAIN, **ORACLE, **ABLATIONS}, tuple(MAIN)[1:], ("GPF", "MMPF", "PF")


@dataclass(frozen=True)
class Cell:
    """Sensors at ``noise`` × the fixed R's std (None: as generated), Q = ``kappa`` × the paper's, ``profile`` seed."""

    noise: float | None
    kappa: float
    profile: int | None = None  # None: the fixed schedule

    @classmethod
    def of(cls, noise, kappa: float, profile: int | None = None) -> Cell:
        """A cell from TOML values (noise "generated" or absent: None)."""
        return cls(None if noise in ("generated", None) else float(noise), float(kappa), profile)

    @property
    def noise_text(self) -> str:
        return "as generated" if self.noise is None else f"{self.noise:g} R"

    @property
    def name(self) -> str:
        where = "fixed profile" if self.profile is None else f"profile {self.profile}"
        return f"sensors {self.noise_text}, κ = {self.kappa:g}, {where}"


KEY = {tag: Cell.of(c.get("noise"), c["kappa"]) for tag, c in EXP["key_cells"].items()}


def _segments(res, div) -> tuple[dict, dict]:
    """Per-run channel RMSE over the maneuver samples and over the level ones (reference restricted; diverged +inf)."""
    out = ({ch: [] for ch in CH}, {ch: [] for ch in CH})
    for rec in res.records:
        p = rec["problem"]
        t = np.asarray(p.t, float)
        man = np.any([(t >= a) & (t < b) for a, b, _ in p.frame_meta["maneuvers"]], axis=0)
        for o, keep in zip(out, (man, ~man)):
            m = scorer.score_run(dataclasses.replace(p, truth_valid=p.truth_valid & keep), rec["estimates"])
            [o[ch].append(m[f"{ch}_rmse"]) for ch in CH]
    return tuple({ch: np.where(div, np.inf, np.asarray(o[ch], float)) for ch in CH} for o in out)


def compute(job) -> dict:
    """``(cell, labels, runs, seed, duration)`` -> the cell's results (module docstring); the labels' filters differ."""
    cell, labels, runs, seed, duration = job
    data = {} if cell.noise is None else {"noise_rms": [tidy(cell.noise * s) for s in R_STD]}
    data |= {} if cell.profile is None else {"profile_seed": int(cell.profile)}
    data |= {} if duration is None else {"duration": float(duration)}
    task = {} if cell.kappa == 1.0 else {"Q": [tidy(cell.kappa * q) for q in Q_DIAG]}
    f = dict(VARIANTS[lab] for lab in labels)
    kw = {"runs": runs, "seed": seed, "dataset_params": data, "task_params": task, "filter_params": f}
    ev = evaluate(EXP["dataset"], task=EXP["task"], filters=list(f), **kw)
    out = {"cell": cell, "seed": seed, "command": command_line(ev.config), "filters": {}, "t": np.asarray(ev.t, float)}
    out["maneuvers"] = plain(ev.frame_meta["maneuvers"])
    for lab, res, row in zip(labels, ev.results, ev.rows):
        man, level = _segments(res, np.array([bool(m["diverged"]) for m in res.runs]))
        ess = np.array([e.info.get("mean_ess", np.nan) / N for e in res.estimates])
        rmse, lost = {ch: per_run(res, f"{ch}_rmse")[0] for ch in CH}, per_run(res, "depth_rmse")[1]
        out["filters"][lab] = {"row": plain(row), "lost": lost, "rmse": rmse, "ess": ess, "man": man, "level": level}
    return out


def plan(runs=None, quick=False) -> dict:
    """Runs, cells and evaluation jobs ``(cell, labels, runs, seed offset)`` of ``[experiment]`` (``[quick]``)."""
    q = {**EXP, "duration": None, **(X["quick"] if quick else {})}
    p = {"runs": runs or q["runs"], "duration": q["duration"], "kappas": q["grid"]["kappas"]}
    p |= {k: max(2, round(p["runs"] * EXP[k] / EXP["runs"])) for k in ("profile_runs", "tune_runs")}
    p["noises"] = [Cell.of(n, 1).noise for n in q["grid"]["noises"]]
    p["grid"] = [Cell(n, float(k)) for n in p["noises"] for k in p["kappas"]]
    p["profiles"] = [Cell.of(None, k, s) for k in q["profiles"]["kappas"] for s in q["profiles"]["seeds"]]
    p["ablation"] = [Cell.of(c.get("noise"), c["kappa"]) for c in q["ablation_cells"]]
    both = ((p["runs"], 0), (p["tune_runs"], EXP["tune_seed"]))
    p["jobs"] = (
        [(c, tuple(MAIN), n, s) for n, s in both for c in p["grid"]]
        + [(c, tuple(ORACLE), n, s) for c in p["grid"] if c.noise is None for n, s in both]
        + [(c, tuple(MAIN), p["profile_runs"], 0) for c in p["profiles"]]
        + [(c, (lab,), p["runs"], 0) for c in p["ablation"] for lab in ABLATIONS]
    )
    return p


def cmp(name: str, fa: dict, fb: dict, ch: str, key: str = "rmse") -> Comparison:
    """``fa`` − ``fb`` per run: ``key`` "rmse", "man", "level", "lead" or "ratio" (maneuver / level RMSE)."""
    with np.errstate(all="ignore"):
        a, b = ((f["man"][ch] / f["level"][ch] if key == "ratio" else f[key][ch]) for f in (fa, fb))
    return Comparison(name, a, b, fa["lost"], fb["lost"])


def lead(res: dict, ch: str) -> dict:
    """Per-run lead of GPF over the baseline with the lowest mean RMSE in the cell: 1 − GPF / best."""
    best = min(OTHERS, key=lambda lab: np.mean(res[lab]["rmse"][ch]))
    with np.errstate(all="ignore"):
        v = 1 - res["GPF"]["rmse"][ch] / res[best]["rmse"][ch]
    return {"lead": {ch: v}, "lost": res["GPF"]["lost"] | res[best]["lost"], "best": best}


def tuned(T: dict, R: dict, grid) -> dict:
    """(label, channel) -> (cell, variant, its verdict-seed results): the lowest mean RMSE on the tuning seed."""
    out = {}
    for lab in MAIN:
        options = [(c, v) for c in grid if c.noise is None for v in (lab, f"{lab}, R matched") if v in T[c]]
        for ch in CH:
            c, v = min(options, key=lambda o: np.mean(T[o[0]][o[1]]["rmse"][ch]))
            out[(lab, ch)] = (c, v, R[c][v])
    return out


def evidence(R: dict, T: dict, p: dict) -> dict:
    """The comparisons the rules name: each ``[[evidence]]`` of the TOML (cells, channels, pairs), then best,
    cost (µs per step over the grid), lead-q (first vs last κ per sensor level), lead-r (1 R vs lowest per κ)."""
    ev, at, cell = {}, tuned(T, R, p["grid"]), {(c.noise, c.kappa): R[c] for c in p["grid"]}
    for e in X["evidence"]:
        cells = (
            [("ablation", c) for c in p["ablation"]] if e["cells"] == "ablation" else [(t, KEY[t]) for t in e["cells"]]
        )
        for t, c, ch, (a, b) in [(t, c, ch, ab) for t, c in cells for ch in CH for ab in e["pairs"]]:
            if c.kappa < e.get("kappa_below", np.inf):
                name = e["name"].format(sensors=c.noise_text, kappa=c.kappa, ch=ch, a=a, b=b)
                key = e["key"].format(tag=t, ch=ch)
                ev.setdefault(key, []).append(cmp(name, R[c][a], R[c][b], ch, e.get("of", "rmse")))
    ev["best"] = [cmp(f"{ch}: GPF − {lab}", at[("GPF", ch)][2], at[(lab, ch)][2], ch) for ch in CH for lab in OTHERS]
    us = [[R[c][lab]["row"]["us_per_step"] for c in p["grid"]] for lab in ("GPF", "MMPF")]
    ev["cost"] = [Comparison("GPF − MMPF, µs per step over the grid cells", *us)]
    lo, k = [n for n in p["noises"] if n is not None], p["kappas"]
    rows = [("lead-q", f"sensors {Cell(n, 1).noise_text}", (n, k[0]), (n, k[-1])) for n in p["noises"]]
    rows += [("lead-r", f"κ = {x:g}", (max(lo), x), (min(lo), x)) for x in k]
    for key, name, x, y in rows:
        ev.setdefault(key, []).extend(
            cmp(f"{name}, {ch}", lead(cell[x], ch), lead(cell[y], ch), ch, "lead") for ch in CH
        )
    return ev


def _grid(cells, head: list, cols, anchor: str = "", first=None) -> str:
    """A table with a row per cell: its sensors and κ, then ``cols(cell)``; the ``anchor`` on the row of ``first``."""
    rows = [[(tag(anchor) if c == first else "") + c.noise_text, f"{c.kappa:g}", *cols(c)] for c in cells]
    return render.table(["sensors", "κ", *head], rows)


def tables(R: dict, T: dict, p: dict) -> dict:
    """The evidence tables of the template (anchors on the claims' rows); differences paired, mean ± 95 %."""
    g, three, a = p["grid"], ("GPF", "MMPF", "EKF"), {k: (c, v, f) for k, (c, v, f) in tuned(T, R, p["grid"]).items()}
    at = {k: f["rmse"][k[1]] for k, (c, v, f) in a.items()}
    other = {ch: min(OTHERS, key=lambda lab: np.mean(at[(lab, ch)])) for ch in CH}
    d = lambda c, x, y, ch: pm(R[c][x]["rmse"][ch], R[c][y]["rmse"][ch])
    order = lambda c: [f"{d(c, 'GPF', 'MMPF', ch)} / {d(c, 'MMPF', 'EKF', ch)}" for ch in CH]
    ratio = lambda f, ch: np.mean(cmp("", f, f, ch, "ratio").a)
    us = lambda c, lab: R[c][lab]["row"]["us_per_step"]
    best = lambda lab, ch: f"{fmt(np.mean(at[(lab, ch)]))} (κ = {a[(lab, ch)][0].kappa:g}{a[(lab, ch)][1][len(lab) :]})"
    man = [
        [(tag("#e-man") if (c, ch) == (KEY["paper"], CH[0]) else "") + c.name, ch]
        + [" / ".join(fmt(np.mean(R[c][lab][k][ch])) for lab in three) for k in ("man", "level")]
        + [" / ".join(f"{ratio(R[c][lab], ch):.2f}" for lab in three)]
        for c in KEY.values()
        if c in g
        for ch in CH
    ]
    abl = [
        [(tag("#e-ablation") if (c, lab) == (p["ablation"][0], next(iter(ABLATIONS))) else "") + c.name, lab]
        + [d(c, lab, "GPF", ch) for ch in CH]
        for c in p["ablation"]
        for lab in ABLATIONS
    ]
    ess = lambda c: (
        [f"{100 * np.mean(R[c][lab]['ess']):.2g} %" for lab in PFS]
        + [" / ".join(f"{int(R[c][lab]['lost'].sum())}/{len(R[c][lab]['lost'])}" for lab in PFS)]
    )
    grows = lambda c: [f"{100 * np.nanmean(lead(R[c], ch)['lead'][ch]):+.0f} % ({lead(R[c], ch)['best']})" for ch in CH]
    return {
        "best": render.table(
            ["channel", *MAIN, "GPF − the best other (paired)"],
            [
                [(tag("#e-best") if ch == CH[0] else "") + ch, *(best(lab, ch) for lab in MAIN)]
                + [f"{pm(at[('GPF', ch)], at[(other[ch], ch)])} ({other[ch]})"]
                for ch in CH
            ],
        ),
        "grid": _grid(g, [f"{ch}: GPF − MMPF / MMPF − EKF" for ch in CH], order, "#e-order", KEY["paper"]),
        "maneuvers": render.table(
            ["cell", "channel", *(f"{k} GPF / MMPF / EKF" for k in ("maneuvers", "level", "ratio"))], man
        ),
        "profiles": render.table(
            ["κ", "profile", *(f"{ch}: GPF − MMPF / MMPF − EKF" for ch in CH)],
            [[f"{c.kappa:g}", c.profile, *order(c)] for c in p["profiles"]],
        ),
        "ablation": render.table(["cell", "variant", *(f"{ch}: variant − GPF" for ch in CH)], abl),
        "lead": _grid(g, CH, grows, "#e-lead", g[0]),
        "ess": _grid(g, [*(f"ESS/N {lab}" for lab in PFS), "lost GPF / MMPF / PF"], ess),
        "cost": _grid(
            g,
            [*(f"{lab} µs/step" for lab in MAIN), "GPF/MMPF"],
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
    outs = [None] * len(args)
    with pool(workers) as ex:
        for i, out in run_longest_first(compute, args, [len(a[1]) * a[2] for a in args], labels, ex, quiet):
            outs[i] = out
    R, T, commands = {}, {}, {}
    for out in outs:  # in the plan's order: the document does not depend on which evaluation finished first
        (T if out["seed"] == tune else R).setdefault(out["cell"], {}).update(out["filters"])
        commands.setdefault((out["cell"], out["seed"]), []).append(out["command"])
    cmd = "replay reproduce 000" + " --quick" * quick + f" --runs {runs}" * bool(runs) + f" --seed {seed}" * bool(seed)
    verdicts, old = decide(CLAIMS, evidence(R, T, p), seed), spec.old_labels(X)
    fields = {f"table_{k}": v for k, v in tables(R, T, p).items()} | {
        k: p[k] for k in ("runs", "tune_runs", "profile_runs")
    }
    fields |= {"command": cmd, "jobs": len(args), "workers": workers, "seed": seed, "tune_seed": tune}
    fields |= {
        "generated": ", ".join(f"{g:.3g}" for g in GENERATED_RMS),
        "rho": ", ".join(f"{g / r:.3g}" for g, r in zip(GENERATED_RMS, R_STD)),
        "matched": ", ".join(f"{g:.3g}²" for g in GENERATED_RMS),
        "units": ", ".join(EXP["channels"].values()),
        "every_cell": "\n\n".join(
            f"### {c.name}{', tuning seed' * (s == tune)}\n\n"
            + result_rows([f["row"] for f in res[c].values()], tuple(f"{ch}_rmse" for ch in CH), list(res[c]), 4)
            + "\n\n"
            + "  \n".join(f"`{x}`" for x in sorted(commands[(c, s)]))
            for res, s in ((R, seed), (T, tune))
            for c in res
        ),
        "relabelled": render.table(
            ["claim", "before", "now", "the number behind it"],
            [[v.claim.words, old[v.claim.id], v.label, render.found(v)] for v in verdicts],
        ),
        "ess_paper": " ".join(
            f"{c.name}: mean ESS/N " + ", ".join(f"{lab} {100 * np.mean(R[c][lab]['ess']):.2g} %" for lab in PFS) + "."
            for c in KEY.values()
        ),
    }
    doc = Path(doc or "docs/reproduction/000.md")
    write_document(doc, render.render("000", fields, verdicts) + footer(cmd, sw.seconds))
    if not quiet:
        print(doc.read_text(encoding="utf-8"))
        print(f"wrote {doc}", file=sys.stderr)
    return R, T
