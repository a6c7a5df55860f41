"""``replay reproduce 000``: GPF vs MMPF vs EKF on synthetic lake-trial logs (paper 000), as data + a template.

``replay/papers/000.toml`` declares the cells (:class:`Cell`), filters, GPF variants, tuning seed, the cost
claim's margin, table heads, the claims with their rules and the paired comparisons they name (its comments say
how; :func:`experiment` checks every key). :func:`compute` runs a cell through
:func:`replay.run.evaluation.evaluate` (the pipeline of ``replay eval``) in a worker process and sends back per-run
numbers only (a run's records are about 0.7 MB); :func:`evidence` fills the comparisons,
:func:`replay.reproduce.rules.decide` decides, and :func:`tables` fills the prose ``replay/papers/000.md``. A filter
variant, cell, grid value, claim or paired comparison in named cells is a TOML edit; a new statistic or table is code.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from itertools import product

import numpy as np

from replay.campaign.longest import pool, run_longest_first, workers
from replay.models.depth import R_FIXED, paper_Q
from replay.run.eval_options import EvalOptions
from replay.run.evaluation import evaluate
from replay.run.manifest import command_line
from replay.run.pipeline import plain
from replay.scoring import scorer
from replay.sim.lake_depth import sensor_rms
from replay.util.portable import write_document

from . import render, spec
from .render import anchor_tag, fmt, pm, table
from .rules import Comparison, decide, per_run
from .tables import Stopwatch, footer, result_rows

RUNS, STATS = ("experiment", "quick"), {"rmse", "man", "level", "ratio"}
SCHEMA = {  # each kind of TOML entry -> its keys ("?": optional)
    "file": "experiment quick filters tables evidence claim",
    "experiment": "dataset task channels particles runs profile_runs tune_runs tune_seed cost_margin grid profiles "
    "ablation_cells key_cells",
    "quick": "runs? duration? grid? profiles? ablation_cells?",
    **{"grid": "noises kappas", "profiles": "kappas seeds", "cell": "kappa noise?"},
    **{"filters": "main oracle ablation", "filter": "filter params?"},
    "tables": "best grid maneuvers profiles ablation lead ess cost relabelled",
    "evidence": "key cells pairs name of? kappa_below?",
}


def experiment(x: dict) -> dict:
    """``x`` if every entry has the keys of its kind in :data:`SCHEMA` (claims: :func:`spec.claims`) and the names
    it uses exist, else a ``ValueError`` naming the file and the entry."""
    todo = [("file", x, "the top level"), *((k, x.get(k, {}), f"[{k}]") for k in ("filters", "tables", *RUNS))]
    todo += [("filter", e, f"[filters.{k}] {lab!r}") for k, t in x.get("filters", {}).items() for lab, e in t.items()]
    todo += [("evidence", e, f"[[evidence]] {e.get('key')!r}") for e in x.get("evidence", [])]
    for n, t in ((n, x.get(n, {})) for n in RUNS):
        todo += [(k, t[k], f"[{n}] {k}") for k in ("grid", "profiles") if k in t]
        cells = [*t.get("ablation_cells", []), *t.get("key_cells", {}).values()]
        todo += [("cell", c, f"[{n}] cell {c}") for c in cells]
    for kind, t, entry in todo:
        spec.check(t, SCHEMA[kind], f"000.toml: {entry}")
    labels, cells = {lab for t in x["filters"].values() for lab in t}, {"ablation", *x["experiment"]["key_cells"]}
    for e in x["evidence"]:  # the names an [[evidence]] entry uses: cells, filter labels, the statistic
        used = {lab for pair in e["pairs"] for lab in pair}
        bad = set(e["cells"]) - cells | used - labels | {e.get("of", "rmse")} - STATS
        if bad:
            raise ValueError(f"000.toml: [[evidence]] {e['key']!r}: unknown name(s) {sorted(bad)}")
    margin = f"{x['experiment']['cost_margin']:g} × MMPF"
    if any(c.get("rule", {}).get("decides") == "cost" and margin not in c["rule"]["statistic"] for c in x["claim"]):
        raise ValueError(f"000.toml: [[claim]] deciding 'cost': its statistic does not name the margin {margin!r}")
    return x


def tidy(x) -> float:
    """A short decimal for commands: 0.006, not 0.006000000000000001."""
    return float(f"{float(x):.10g}")


X = experiment(spec.load("000"))
CLAIMS, EXP = spec.claims(X, "000.toml"), X["experiment"]
CH, N, MARGIN = tuple(EXP["channels"]), EXP["particles"], EXP["cost_margin"]
R_STD, Q_DIAG = np.sqrt(np.diag(R_FIXED)), np.diag(paper_Q()[0])  # the baselines' fixed R, the paper's Q
RMS = sensor_rms()  # sim/lake-depth's sensors as generated (RMS of their noise over the run)
MATCHED_R = [tidy(g * g) for g in RMS]  # their mean-square noise: an oracle's R
SENSORS = {  # the template's numbers of those sensors
    "generated": ", ".join(f"{g:.3g}" for g in RMS),
    "rho": ", ".join(f"{g / r:.3g}" for g, r in zip(RMS, R_STD)),
    "matched": ", ".join(f"{g:.3g}²" for g in RMS),
    "units": ", ".join(EXP["channels"].values()),
}


def variants(kind: str) -> dict:
    """``[filters.<kind>]``: label -> (registered filter, its parameters; R = "matched": :data:`MATCHED_R`)."""
    out = {}
    for lab, e in X["filters"][kind].items():
        out[lab] = (e["filter"], {k: MATCHED_R if v == "matched" else v for k, v in e.get("params", {}).items()})
    return out


def heads(head: str) -> list[str]:
    """A ``[tables]`` head as columns: one per channel if it holds {ch}, one per main filter if {main}."""
    return [head.format(ch=x, main=x) for x in (CH if "{ch}" in head else MAIN if "{main}" in head else [""])]


MAIN, ORACLE, ABLATIONS = variants("main"), variants("oracle"), variants("ablation")
VARIANTS, OTHERS = {**MAIN, **ORACLE, **ABLATIONS}, tuple(MAIN)[1:]  # the baselines: every main filter but GPF
PFS, THREE = ("GPF", "MMPF", "PF"), ("GPF", "MMPF", "EKF")
HEADS = {k: [col for h in v for col in heads(h)] for k, v in X["tables"].items()}


@dataclass(frozen=True)
class Cell:
    """Sensors at ``noise`` × the fixed R's std (None: as generated), Q = ``kappa`` × the paper's, ``profile`` seed.
    Cells of one sensor level draw the same noise, so its filters and cells are paired run by run."""

    noise: float | None
    kappa: float
    profile: int | None = None  # None: the fixed schedule

    @classmethod
    def of(cls, noise="generated", kappa=1.0, profile=None) -> Cell:
        """A cell from the TOML's values."""
        return cls(None if noise == "generated" else float(noise), float(kappa), profile)

    @property
    def noise_text(self) -> str:
        return "as generated" if self.noise is None else f"{self.noise:g} R"

    @property
    def name(self) -> str:
        where = "fixed profile" if self.profile is None else f"profile {self.profile}"
        return f"sensors {self.noise_text}, κ = {self.kappa:g}, {where}"

    def dataset_params(self, duration: float | None = None) -> dict:
        """sim/lake-depth's parameters of the cell: sensors' RMS, profile seed, log length (absent: the default)."""
        out = {} if self.noise is None else {"noise_rms": [tidy(self.noise * s) for s in R_STD]}
        out |= {} if self.profile is None else {"profile_seed": int(self.profile)}
        return out | ({} if duration is None else {"duration": float(duration)})

    def task_params(self) -> dict:
        """The depth task's Q = κ × the paper's (absent at κ = 1)."""
        return {} if self.kappa == 1.0 else {"Q": [tidy(self.kappa * q) for q in Q_DIAG]}


KEY = {name: Cell.of(**c) for name, c in EXP["key_cells"].items()}


def segments(res) -> dict:
    """Per-run RMSE per channel (diverged +inf) over the maneuvers (``man``: non-zero pitch command +1.5 s
    settling, the frame's ``maneuvers``), over the level runs (``level``), and their ``ratio``."""
    div, seg = np.array([bool(m["diverged"]) for m in res.runs]), {"man": [], "level": []}
    for rec in res.records:
        p, est = rec.problem, rec.estimates
        man = scorer.within(p.t, p.frame_meta["maneuvers"])
        seg["man"].append(scorer.score_where(p, est, man))
        seg["level"].append(scorer.score_where(p, est, ~man))
    out = {k: {ch: np.where(div, np.inf, [m[f"{ch}_rmse"] for m in v]) for ch in CH} for k, v in seg.items()}
    with np.errstate(all="ignore"):
        return out | {"ratio": {ch: out["man"][ch] / out["level"][ch] for ch in CH}}


def compute(job) -> dict:
    """``(cell, labels, runs, seed, duration)`` -> per filter (the labels' filters differ): the leaderboard row,
    per-run RMSE per channel (diverged +inf) and lost flags, :func:`segments`, mean ESS / N."""
    cell, labels, runs, seed, duration = job
    f = dict(VARIANTS[lab] for lab in labels)
    kw = dict(dataset_params=cell.dataset_params(duration), task_params=cell.task_params(), filter_params=f)
    ev = evaluate(EXP["dataset"], EvalOptions(task=EXP["task"], filters=list(f), runs=runs, seed=seed, **kw))
    out = {"cell": cell, "seed": seed, "command": command_line(ev.config), "t": np.asarray(ev.t, float), "filters": {}}
    out["maneuvers"] = plain(ev.frame_meta["maneuvers"])
    for lab, res, row in zip(labels, ev.results, ev.rows):
        rmse, lost = {ch: per_run(res, f"{ch}_rmse")[0] for ch in CH}, per_run(res, "depth_rmse")[1]
        ess = np.array([e.info.get("mean_ess", np.nan) / N for e in res.estimates])
        out["filters"][lab] = {"row": plain(row), "rmse": rmse, "lost": lost, "ess": ess, **segments(res)}
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
    both = ((p["runs"], 0), (p["tune_runs"], EXP["tune_seed"]))  # the verdict seed, the tuning seed
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
    for lab, ch in product(MAIN, CH):
        options = [(c, v) for c in grid if c.noise is None for v in (lab, f"{lab}, R matched") if v in T[c]]
        c, v = min(options, key=lambda o: np.mean(T[o[0]][o[1]]["rmse"][ch]))
        out[(lab, ch)] = (c, v, R[c][v])
    return out


def paired(name: str, fa: dict, fb: dict, ch: str, of: str = "rmse") -> Comparison:
    """The claim "``fa``'s per-run ``of`` in channel ``ch`` is below ``fb``'s" (their lost flags choose the test)."""
    return Comparison(name, fa[of][ch], fb[of][ch], fa["lost"], fb["lost"])


def declared(R: dict, p: dict) -> dict:
    """The comparisons of every ``[[evidence]]`` entry: its cells × channels × pairs (the TOML's comments)."""
    ev = {}
    for e in X["evidence"]:
        for n in e["cells"]:
            for c in p["ablation"] if n == "ablation" else [KEY[n]]:
                if c.kappa >= e.get("kappa_below", np.inf):
                    continue
                for ch, (a, b) in product(CH, e["pairs"]):
                    name = e["name"].format(sensors=c.noise_text, kappa=c.kappa, ch=ch, a=a, b=b)
                    comparison = paired(name, R[c][a], R[c][b], ch, e.get("of", "rmse"))
                    ev.setdefault(e["key"].format(tag=n, ch=ch), []).append(comparison)
    return ev


def evidence(R: dict, T: dict, p: dict) -> dict:
    """The comparisons the rules name: :func:`declared`, then best (each filter tuned), cost (GPF's µs per step
    against the margin × MMPF's over the grid), lead-q@paper (GPF − the best baseline in the paper's cell), lead-q
    (first vs last κ, the paper's sensors) and lead-r@paper / lead-r@other (1 R vs the lowest sensor level at the
    paper's κ / at every other κ) of GPF's :func:`lead`."""
    ev, at = declared(R, p), tuned(T, R, p["grid"])
    ev["best"] = [paired(f"{ch}: GPF − {lab}", at[("GPF", ch)][2], at[(lab, ch)][2], ch) for ch in CH for lab in OTHERS]
    gpf, mmpf = ([R[c][lab]["row"]["us_per_step"] for c in p["grid"]] for lab in ("GPF", "MMPF"))
    name = f"GPF − {MARGIN:g} × MMPF, µs per step over the grid cells"
    ev["cost"] = [Comparison(name, gpf, [MARGIN * u for u in mmpf])]
    k, lo, at = p["kappas"], [n for n in p["noises"] if n is not None], KEY["paper"]
    rows = [("lead-q", f"sensors {at.noise_text}", Cell(at.noise, k[0]), Cell(at.noise, k[-1]))]
    tag = lambda x: "lead-r@paper" if x == at.kappa else "lead-r@other"
    rows += [(tag(x), f"κ = {x:g}", Cell(max(lo), x), Cell(min(lo), x)) for x in k]
    for key, name, x, y in rows:
        ev.setdefault(key, []).extend(paired(f"{name}, {ch}", lead(R[x], ch), lead(R[y], ch), ch, "lead") for ch in CH)
    best = {ch: lead(R[at], ch)["best"] for ch in CH}  # the lead in the paper's setting: GPF − the best baseline
    gpf = lambda ch: paired(f"κ = {at.kappa:g}, {ch}: GPF − {best[ch]}", R[at]["GPF"], R[at][best[ch]], ch)
    ev["lead-q@paper"] = [gpf(ch) for ch in CH]
    return ev


def anchored(kind: str, rows: list[list], anchor: str = "", at: int | None = 0) -> str:
    """The evidence table ``[tables] kind`` of ``rows``, the claims' ``anchor`` on row ``at`` (None: on none)."""
    rows = [[anchor_tag(anchor) + str(r[0]), *r[1:]] if anchor and i == at else r for i, r in enumerate(rows)]
    return table(HEADS[kind], rows)


def best_rows(R: dict, T: dict, grid) -> list[list]:
    """Per channel: each main filter's mean RMSE at its tuned setting (κ, R), and GPF − the best other (paired)."""
    at, rows = tuned(T, R, grid), []
    for ch in CH:
        rmse = {lab: at[(lab, ch)][2]["rmse"][ch] for lab in MAIN}
        other = min(OTHERS, key=lambda lab: np.mean(rmse[lab]))
        setting = {lab: f"κ = {at[(lab, ch)][0].kappa:g}{at[(lab, ch)][1][len(lab) :]}" for lab in MAIN}
        means = [f"{fmt(np.mean(rmse[lab]))} ({setting[lab]})" for lab in MAIN]
        rows.append([ch, *means, f"{pm(rmse['GPF'], rmse[other])} ({other})"])
    return rows


def ess_share(res: dict, lab: str) -> str:
    """A filter's mean ESS as a share of N in one cell (mean over runs)."""
    return f"{100 * np.mean(res[lab]['ess']):.2g} %"


def tables(R: dict, T: dict, p: dict) -> dict:
    """The evidence tables of the template (anchors on the claims' rows); differences paired, mean ± 95 %."""
    g, paper = p["grid"], KEY["paper"]

    def by_cell(columns) -> list[list]:  # one row per grid cell
        return [[c.noise_text, f"{c.kappa:g}", *columns(R[c])] for c in g]

    def order(res) -> list[str]:  # paired GPF − MMPF / MMPF − EKF per channel
        d = lambda a, b, ch: pm(res[a]["rmse"][ch], res[b]["rmse"][ch])
        return [f"{d('GPF', 'MMPF', ch)} / {d('MMPF', 'EKF', ch)}" for ch in CH]

    def grows(res) -> list[str]:  # GPF's lead over the best baseline per channel
        return [f"{100 * np.nanmean(lead(res, ch)['lead'][ch]):+.0f} % ({lead(res, ch)['best']})" for ch in CH]

    def ess(res) -> list[str]:
        lost = " / ".join(f"{int(res[lab]['lost'].sum())}/{len(res[lab]['lost'])}" for lab in PFS)
        return [ess_share(res, lab) for lab in PFS] + [lost]

    def cost(res) -> list[str]:
        us = {lab: res[lab]["row"]["us_per_step"] for lab in MAIN}
        return [f"{us[lab]:.0f}" for lab in MAIN] + [f"{us['GPF'] / us['MMPF']:.2f}"]

    means = lambda c, key, ch, f=fmt: " / ".join(f(np.mean(R[c][lab][key][ch])) for lab in THREE)
    man = [
        [c.name, ch, means(c, "man", ch), means(c, "level", ch), means(c, "ratio", ch, "{:.2f}".format)]
        for c in KEY.values()
        if c in g
        for ch in CH
    ]
    ablation = [
        [c.name, lab, *(pm(R[c][lab]["rmse"][ch], R[c]["GPF"]["rmse"][ch]) for ch in CH)]
        for c in p["ablation"]
        for lab in ABLATIONS
    ]
    paper_row = [r[0] for r in man].index(paper.name) if paper in g else None  # its first channel
    return {
        "best": anchored("best", best_rows(R, T, g), "#e-best"),
        "grid": anchored("grid", by_cell(order), "#e-order", at=g.index(paper) if paper in g else None),
        "maneuvers": anchored("maneuvers", man, "#e-man", at=paper_row),
        "profiles": anchored("profiles", [[f"{c.kappa:g}", c.profile, *order(R[c])] for c in p["profiles"]]),
        "ablation": anchored("ablation", ablation, "#e-ablation"),
        "lead": anchored("lead", by_cell(grows), "#e-lead"),
        "ess": anchored("ess", by_cell(ess)),
        "cost": anchored("cost", by_cell(cost), "#e-cost"),
    }


def collect(jobs: list, tune_seed: int, quiet: bool) -> tuple[dict, dict, dict]:
    """:func:`compute` of every job in worker processes, the costliest first. R (verdict seed) and T (tuning seed):
    cell -> label -> numbers, in the plan's order; and (cell, seed) -> the ``replay eval`` commands."""
    labels = [f"{c.name}: {', '.join(labs)} ({n} runs, seed {s})" for c, labs, n, s, _ in jobs]
    with pool(workers()) as ex:
        outs = dict(run_longest_first(compute, jobs, [len(j[1]) * j[2] for j in jobs], labels, ex, quiet))
    R, T, commands = {}, {}, {}
    for out in (outs[i] for i in range(len(jobs))):  # the plan's order, not the order the evaluations finished
        (T if out["seed"] == tune_seed else R).setdefault(out["cell"], {}).update(out["filters"])
        commands.setdefault((out["cell"], out["seed"]), []).append(out["command"])
    return R, T, commands


def every_cell(R: dict, T: dict, commands: dict, seeds: tuple[int, int]) -> str:
    """Each cell's leaderboard rows and ``replay eval`` commands: the verdict seed's cells, then the tuning seed's."""
    out = []
    for res, s in zip((R, T), seeds):
        for c in res:
            rows = result_rows([f["row"] for f in res[c].values()], [f"{ch}_rmse" for ch in CH], list(res[c]), 4)
            cmds = "  \n".join(f"`{x}`" for x in sorted(commands[(c, s)]))
            out.append(f"### {c.name}{', tuning seed' * (s == seeds[1])}\n\n{rows}\n\n{cmds}")
    return "\n\n".join(out)


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Compute every job of :func:`plan`, decide the claims, write the document (``data_dir``: unused, synthetic)."""
    sw, p, tune = Stopwatch(), plan(runs, quick), seed + EXP["tune_seed"]
    jobs = [(c, labs, n, seed + s, p["duration"]) for c, labs, n, s in p["jobs"]]
    R, T, commands = collect(jobs, tune, quiet)
    cmd = "replay reproduce 000" + " --quick" * quick + f" --runs {runs}" * bool(runs) + f" --seed {seed}" * bool(seed)
    verdicts, old = decide(CLAIMS, evidence(R, T, p), seed), spec.old_labels(X)
    relabel = [[v.claim.words, old[v.claim.id], v.label, render.found(v)] for v in verdicts]
    fields = {f"table_{k}": v for k, v in tables(R, T, p).items()} | SENSORS
    fields |= {k: p[k] for k in ("runs", "tune_runs", "profile_runs")} | {"cost_margin": f"{MARGIN:g}"}
    fields |= dict(command=cmd, jobs=len(jobs), workers=workers(), seed=seed, tune_seed=tune)
    fields |= {
        "every_cell": every_cell(R, T, commands, (seed, tune)),
        "relabelled": table(HEADS["relabelled"], relabel),
    }
    ess = {c: ", ".join(f"{lab} {ess_share(R[c], lab)}" for lab in PFS) for c in KEY.values()}
    fields["ess_paper"] = " ".join(f"{c.name}: mean ESS/N {ess[c]}." for c in KEY.values())
    text = render.render("000", fields, verdicts) + footer(cmd, sw.seconds)
    doc = write_document(doc or "docs/reproduction/000.md", text)
    if not quiet:
        print(text)
        print(f"wrote {doc}", file=sys.stderr)
    return R, T
