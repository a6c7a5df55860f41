"""Reproduction of paper 003 (weight-factor PF vs PF, UAV formation under glint noise), §4 Fig. 1–6.

Every declaration is data in ``replay/papers/003.toml`` (:data:`T`, read by :func:`load`, every key
checked): the rows (a filter and its parameters), the settings (dataset and task parameters, N, their
rows; the pooled rows of a pooled setting run on every seed of ``seeds``), the baselines' tuning grids,
the evidence (run-by-run comparisons of two rows), the claims and their rules (:mod:`.spec`), the
tables' layouts. This module runs the evaluations (:func:`replay.run.evaluation.evaluate`, in
``REPLAY_WORKERS`` processes), computes per-run values (position RMSE, lost flags, growth of the error,
distinct particles after resampling, eq. 28–32), decides (:func:`.rules.decide`) and fills the prose
``replay/papers/003.md`` (:func:`.render.render`). Adding a setting, a row, an ablation or a comparison
is a TOML edit: a ``setting`` line (into an existing sweep table; a new table is a ``[sweeps]`` entry and
its ``${t_<table>}`` in the template), a ``[row]``, an ``[evidence]`` line, a ``[[claim]]``.
:func:`check` (an entry's keys against a schema, naming the file and the entry) would serve any paper.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from replay.run.evaluation import evaluate
from replay.scoring.significance import holm, t_interval

from . import spec
from .common5 import combine, commands, per_run, rmse_curve, rmse_figures, table
from .pool import pool, run_longest_first, workers
from .render import render
from .render import table as md
from .rules import TEST_NAMES, Comparison, decide, p_text, test_one
from .verdict import Stopwatch, footer, write_document

SCHEMA = {  # table: (required keys, optional keys) of each of its entries ("": the file itself)
    "": (
        "dataset seeds pooled_rows growth tune row grid sweeps setting evidence peak figure where poor distinct heads"
        " claim",
        "",
    ),
    "row": ("filter name", "particles params"),
    "grid": ("row param values shared", ""),
    "setting": ("label table n rows", "data task pooled"),
    "columns": ("head a b family", "mcnemar"),
}


def check(entry: dict, need: str, may: str, where: str) -> dict:
    """``entry`` if its keys are all of ``need`` and some of ``may``, else ``ValueError`` naming ``where``."""
    bad, missing = set(entry) - set(need.split()) - set(may.split()), set(need.split()) - set(entry)
    if bad or missing:
        raise ValueError(
            f"003.toml: {where}: " + (f"unknown key(s) {sorted(bad)}" if bad else f"missing {sorted(missing)}")
        )
    return entry


def load(t: dict) -> dict:
    """The parsed ``003.toml`` checked (:data:`SCHEMA`; rows, settings and per-run values named exist), with
    ``claims`` (:func:`.spec.claims`) and ``by_label`` (settings by label) added."""
    check(t, *SCHEMA[""], "top level")
    entries = [("row", k, e) for k, e in t["row"].items()] + [("grid", k, e) for k, e in t["grid"].items()]
    entries += [("setting", s.get("label"), s) for s in t["setting"]] + [
        ("columns", c.get("head"), c) for c in t["where"]["columns"]
    ]
    for kind, k, e in entries:
        check(e, *SCHEMA[kind], f"{kind} {k!r}")
    t["by_label"] = {s["label"]: s for s in t["setting"]}
    uses = [(f"setting {s['label']!r}", s["rows"], s["table"], "") for s in t["setting"]]
    uses += [
        (
            f"evidence {k!r}",
            [x for c in v for x in c[2:4]],
            "printed",
            [c[1] for c in v if len(c) != 5 or c[4] not in VALUES],
        )
        for k, v in t["evidence"].items()
    ]
    for where, rows, tab, bad in uses:
        if set(rows) - set(t["row"]) - {"zero"} or tab not in t["sweeps"] or bad:
            raise ValueError(f"003.toml: {where}: unknown row, table or per-run value in {rows}, {tab!r}, {bad}")
    return t | {"claims": spec.claims(t, "003.toml")}


def lost(ev):
    return np.array([bool(r.get("lost")) for r in ev.results[0].runs])


def rmse(ev):
    return per_run(ev, 0, "pos_rmse")


def growth(ev):
    """Per run: RMS position error over ``growth.late`` minus over ``growth.early`` (NaN for a diverged run)."""
    res, (a, b), (c, d) = ev.results[0], T["growth"]["early"], T["growth"]["late"]
    e = [
        np.full(len(x["position"]), np.nan)
        if r.get("diverged")
        else np.linalg.norm(np.asarray(x["position"], float), axis=-1)
        for r, x in zip(res.runs, res.errors)
    ]
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.mean(np.array(e)[:, c:d] ** 2, axis=1)) - np.sqrt(np.mean(np.array(e)[:, a:b] ** 2, axis=1))


def distinct(ev):
    return np.array([np.mean(getattr(e, "info", {}).get("distinct", np.nan)) for e in ev.results[0].estimates])


def run_errors(ev, i=0) -> dict[str, np.ndarray]:
    """Per-run absolute position errors (runs, steps) of result ``i`` of ``ev`` per axis of ``[figure]`` (m)."""
    pos = np.abs(np.stack([np.asarray(e["position"], float) for e in ev.results[i].errors]))
    return {key: pos[:, :, j] for j, (key, _, _) in enumerate(T["figure"]["axes"])}


VALUES = {"rmse": rmse, "lost": lost, "growth": growth, "distinct": distinct}
T = load(spec.load("003"))


def name(row: str) -> str:
    return T["row"][row]["name"]


def row_job(key, s, row, tuned=None, seed=0, runs=0):
    """The evaluation of ``row`` at setting ``s``; ``tuned`` = (parameter, value) of a grid."""
    r = T["row"][row]
    params = (
        ({"n_particles": s["n"]} if r.get("particles") else {}) | r.get("params", {}) | dict([tuned] if tuned else [])
    )
    job = {"filters": (r["filter"],), "filter_params": {r["filter"]: params}, "seed": seed, "runs": runs}
    return SimpleNamespace(key=key, dataset_params=dict(s.get("data", {})), task_params=dict(s.get("task", {})), **job)


def plan() -> list:
    """Every evaluation of the settings, keyed ``<label>|<row>|<seed offset>``."""
    seeds = lambda s, r: T["seeds"] if s.get("pooled") and r in T["pooled_rows"] else (0,)
    return [
        row_job(f"{s['label']}|{r}|{k}", s, r, seed=k) for s in T["setting"] for r in s["rows"] for k in seeds(s, r)
    ]


def tune_plan(runs: int | None = None) -> list:
    """The grid evaluations on the tuning seeds, keyed ``tune|<setting>|<grid>|<value>``."""
    tune = T["tune"]
    return [
        row_job(f"tune|{s}|{g}|{v}", T["by_label"][s], d["row"], (d["param"], v), tune["seed"], runs or tune["runs"])
        for s in tune["settings"]
        for g, d in T["grid"].items()
        for v in d["values"]
    ]


def tuned_jobs(evs: dict) -> tuple[list, dict]:
    """Each baseline at its grid's best (lowest mean position RMSE on the tuning seeds), keyed
    ``tuned|<setting>|<grid>``, and {(setting, grid): (value, {value: tuning score})}."""
    jobs, best = [], {}
    for s in T["tune"]["settings"]:
        for g, d in T["grid"].items():
            scores = {v: float(evs[f"tune|{s}|{g}|{v}"].rows[0]["pos_rmse"]) for v in d["values"]}
            v = d["values"][int(np.nanargmin(list(scores.values())))]
            best[(s, g)] = v, scores
            jobs.append(row_job(f"tuned|{s}|{g}", T["by_label"][s], d["row"], (d["param"], v)))
    return jobs, best


def _evaluate(args):
    j, seed, data_dir = args
    kw = dict(dataset_params=j.dataset_params or None, filter_params=j.filter_params, task_params=j.task_params or None)
    return evaluate(T["dataset"], filters=j.filters, runs=j.runs, seed=seed + j.seed, data_dir=data_dir, **kw)


def compute(jobs, runs, seed, data_dir, ex, quiet) -> dict:
    """``{key: Evaluation}`` of ``jobs`` (``runs`` where a job names none), the costliest first."""
    for j in jobs:
        j.runs = j.runs or runs
    cost = [j.runs * sum(p.get("n_particles", 30) for p in j.filter_params.values()) for j in jobs]
    args, labels = [(j, seed, data_dir) for j in jobs], [f"{j.key} ({j.runs} runs)" for j in jobs]
    done = dict(run_longest_first(_evaluate, args, cost, labels, ex, quiet, "003: "))
    return {j.key: done[i] for i, j in enumerate(jobs)}


def evidence(evs, seeds=None) -> dict:
    """``[evidence]`` as ``key -> [Comparison]`` on the runs of ``seeds`` pooled (default: every pooled seed),
    and ``[peak]``: RMSE(t)² at the peak of RMSE(t) (the paper's eq. 33 curve) per axis, seed s."""
    get = lambda lab, r, fn: np.concatenate([VALUES[fn](evs[f"{lab}|{r}|{k}"]) for k in seeds or T["seeds"]])
    out, p = {}, T["peak"]
    for key, comps in T["evidence"].items():
        out[key] = []
        for txt, lab, a, b, fn in comps:
            vb, lb = get(lab, b, fn), get(lab, b, "lost")
            va, la = (np.zeros_like(vb), lb) if a == "zero" else (get(lab, a, fn), get(lab, a, "lost"))
            out[key].append(Comparison(txt, va, vb, la, lb))
    err = run_errors(evs[f"{p['setting']}|{p['row']}|0"])
    k = {x: int(np.nanargmax(rmse_curve(err[x]))) for x in p["paper"]}
    return {
        p["key"]: [
            Comparison(f"{x} at step {k[x] + 1} (m²)", err[x][:, k[x]] ** 2, target=v**2) for x, v in p["paper"].items()
        ]
    } | out


def kurtosis(ratio, eps):
    """Excess kurtosis of the bearing noise (1 − ε) N(0, σ₁²) + ε N(0, (ratio σ₁)²)."""
    return 3 * ((1 - eps) + eps * ratio**4) / ((1 - eps) + eps * ratio**2) ** 2 - 3


def cellof(o, digits=2) -> str:
    """An outcome in a table cell: the estimate, its interval, the (adjusted) p; bold where it holds."""
    if o.test == "mcnemar":
        return f"{int(np.sum(o.comparison.lost_a))} vs {int(np.sum(o.comparison.lost_b))}, p = {p_text(o.p_adj)}"
    s = f"{o.estimate:+.{digits}f} [{o.lo:+.{digits}f}, {o.hi:+.{digits}f}], p = {p_text(o.p_adj)}"
    return f"**{s}**" if o.holds else s


def family(outs, alpha=0.05) -> int:
    """Holm over ``outs`` (sets p_adj and holds); how many hold."""
    for o, p in zip(outs, holm([o.p for o in outs])):
        o.p_adj, o.holds = float(p), bool(p < alpha)
    return sum(o.holds for o in outs)


def where(evs, rng) -> tuple[str, dict]:
    """``[where]`` on every setting, seed s: the columns' paired position-RMSE comparisons (auto: paired t, or
    Wilcoxon and the median's bootstrap interval where a run is lost), the exact McNemar test of the lost runs
    of the ``mcnemar`` columns; Holm over each family. The table and {family: (significant, size)}."""
    cols, fams, body = T["where"]["columns"], {}, []
    for s in T["setting"]:
        ev = {r: evs[f"{s['label']}|{r}|0"] for r in s["rows"]}
        test = lambda a, b: test_one(
            Comparison(s["label"], rmse(ev[a]), rmse(ev[b]), lost(ev[a]), lost(ev[b])), "auto", rng
        )
        o = [test(c["a"], c["b"]) if c["a"] in ev and c["b"] in ev else None for c in cols]
        mc = [test_one(x.comparison, "mcnemar", rng) for x, c in zip(o, cols) if c.get("mcnemar") and x]
        for x, c in [(x, c["family"]) for x, c in zip(o, cols) if x] + [(m, "lost") for m in mc]:
            fams.setdefault(c, []).append(x)
        counts = "/".join(str(int(lost(ev[r]).sum())) if r in ev else "–" for r in T["where"]["counts"])
        body.append([s["label"], o, counts, mc])
    n = {k: (family(v), len(v)) for k, v in fams.items()}
    body = [[lab, *[cellof(x) if x else "n/a" for x in o], k, "; ".join(map(cellof, mc))] for lab, o, k, mc in body]
    return md(["setting", *[c["head"] for c in cols], *T["where"]["heads"]], body), n


def pooled(evid, rng) -> tuple[str, dict]:
    """Every comparison of the verdicts (deciding and stated condition) on the pooled seeds, Holm over each
    claim's family as :func:`.rules.decide` adjusts it; and {claim id: outcomes}."""
    body, by = [], {}
    for c in T["claims"]:
        keys = [k for k in (c.rule.decides, c.rule.condition) if k]
        outs = by[c.id] = [test_one(x, c.rule.test, rng) for k in keys for x in evid[k]]
        family([o for o in outs if o.test != "interval"], c.rule.alpha)
        for i, o in enumerate(outs):
            text = o.text() if o.test == "interval" else f"{o.comparison.name}: {cellof(o)}"
            kind = "deciding" if i < len(evid[c.rule.decides]) else "stated condition"
            body.append([c.id, kind, TEST_NAMES[o.test], text])
    return md(T["heads"]["pooled"], body), by


def replication(evs, rng) -> str:
    """Each deciding comparison on each seed alone: estimate [interval], raw p (not deciding)."""
    per, body = [evidence(evs, (k,)) for k in T["seeds"]], []
    tests = {k: c.rule.test for c in T["claims"] for k in (c.rule.decides, c.rule.condition) if k}
    for key, test in tests.items():
        for i, c in enumerate(per[0][key] if key != T["peak"]["key"] else []):
            outs = [test_one(p[key][i], test, rng) for p in per]
            for o in outs:
                o.p_adj = o.p
            body.append([key, c.name.split(": ", 1)[-1], *map(cellof, outs)])
    return md(["evidence", "comparison", *[f"seed s + {k}" for k in T["seeds"]]], body)


def sweep(evs, group, metrics) -> str:
    """One result table per setting of ``group`` (mean ± t, median, lost, paired Δ against α = 1), its commands."""
    out = []
    for s in (s for s in T["setting"] if s["table"] == group):
        rs = combine(
            [(f"{s['label']}: {name(r)}", (evs[f"{s['label']}|{r}|0"], 0)) for r in s["rows"]], metrics=metrics
        )
        out += [table(rs, metrics=metrics, base_name="α = 1"), "", "Commands (one per row):", "", commands(rs), ""]
    return "\n".join(out)


def ci(x, digits=2, scale=1.0) -> str:
    m, h = t_interval(np.asarray(x, float) * scale)
    return f"{m:+.{digits}f} ± {h:.{digits}f}" if np.isfinite(h) else "n/a"


def small_tables(evs, best) -> dict:
    """The drift table (growth on the pooled seeds, peak of RMSE(t) on seed s), the distinct particles
    after resampling (% of N, mean over steps, then runs ± t, seed s), each baseline at its shared setting
    and at its grid's best."""
    f, lab = T["figure"], T["figure"]["setting"]
    peak = lambda e: " / ".join(f"{np.nanmax(rmse_curve(v)):.2f}" for v in e.values())
    drift = [
        [
            name(r),
            peak(run_errors(evs[f"{lab}|{r}|0"])),
            ci(np.concatenate([growth(evs[f"{lab}|{r}|{k}"]) for k in T["seeds"]])),
        ]
        for r in f["rows"]
    ]
    dist = [
        [
            s["label"],
            s["n"],
            *[
                ci(distinct(evs[f"{s['label']}|{r}|0"]), 1, 100 / s["n"]).lstrip("+") if r in s["rows"] else "n/a"
                for r in T["distinct"]["rows"]
            ],
        ]
        for s in T["setting"]
    ]
    row = lambda r: (
        f"{r['pos_rmse']:.2f} ± {r['pos_rmse_ci95']:.2f} (median {r['pos_rmse_median']:.2f}, lost {r['lost']})"
    )
    edge = lambda v, sc: " (grid edge)" if v in (min(sc), max(sc)) and len(sc) > 1 else ""
    tuned = [
        [
            s,
            g,
            T["grid"][g]["param"],
            ", ".join(f"{x:g}: {y:.2f}" for x, y in sc.items()),
            f"{v:g}{edge(v, sc)}",
            row(evs[f"{s}|{T['grid'][g]['shared']}|0"].rows[0]),
            row(evs[f"tuned|{s}|{g}"].rows[0]),
        ]
        for (s, g), (v, sc) in best.items()
    ]
    heads = {k: [h.format(seeds=len(T["seeds"])) for h in v] for k, v in T["heads"].items()}
    return {
        "drift": md(heads["drift"], drift),
        "distinct": md(heads["distinct"], dist),
        "tuned": md(heads["tuned"], tuned),
    }


def poor(evs, rng) -> str:
    """``[poor]``: the lost runs of each row (seed s) and of the tuned baselines, arm a against arm b on the
    pooled seeds (median Δ, lost runs), the distinct particles kept (not deciding)."""
    p, lab, b = T["poor"], T["poor"]["setting"], T["poor"]["b"]
    get = lambda r, fn: np.concatenate([fn(evs[f"{lab}|{r}|{k}"]) for k in T["seeds"]])
    c = Comparison(p["name"], get(p["a"], rmse), get(b, rmse), get(p["a"], lost), get(b, lost))
    o, m = test_one(c, "auto", rng), test_one(c, "mcnemar", rng)
    o.p_adj, m.p_adj = o.p, m.p
    seed_s = ", ".join(f"{name(r)} {int(lost(evs[f'{lab}|{r}|0']).sum())}" for r in T["by_label"][lab]["rows"])
    kept = ", ".join(f"α = {r[2:]}: {np.nanmean(get(r, distinct)):.1f}" for r in p["distinct"])
    tuned = ", ".join(f"{g} {evs[f'tuned|{lab}|{g}'].rows[0]['lost']}" for g in T["grid"])
    return (
        f"lost runs (of {len(lost(evs[f'{lab}|{b}|0']))}) at seed s: {seed_s}; tuned: {tuned}. {p['name']}, "
        f"{len(c.a)} pooled runs: median Δ {cellof(o)}; lost {cellof(m)}. Distinct particles after resampling "
        f"(of N = {T['by_label'][lab]['n']}, pooled): {kept}"
    )


def plots(t, errors: dict, doc: Path, what: str) -> list[str]:
    """Write ``003_rmse_<axis>.png`` beside ``doc`` (:func:`.common5.rmse_figures`: a panel per filter of
    ``errors`` = {label: :func:`run_errors`}); the Markdown lines that show them."""
    from replay.outputs.plots import save

    try:
        figs = rmse_figures(t, errors, T["figure"]["axes"], f"003, {what}")
    except ImportError:
        return ["(plot skipped: matplotlib is not installed)", ""]
    doc.parent.mkdir(parents=True, exist_ok=True)
    for key, _, _ in T["figure"]["axes"]:
        save(figs[key], doc.parent / f"003_rmse_{key}.png")
    return [x for key, q, _ in T["figure"]["axes"] for x in (f"![{q} over time, {what}](003_rmse_{key}.png)", "")] + [
        T["figure"]["caption"],
        "",
    ]


def fields(evs, best, runs, doc, verdicts, evid) -> dict:
    """Every placeholder of ``replay/papers/003.md`` but the verdicts and the command."""
    rng, f, old = np.random.default_rng(0), T["figure"], spec.old_labels(T)
    where_table, n = where(evs, rng)
    pooled_table, outs = pooled(evid, rng)
    ev = {name(r): evs[f"{f['setting']}|{r}|0"] for r in f["rows"]}
    figs = plots(next(iter(ev.values())).t, {k: run_errors(e) for k, e in ev.items()}, doc, f["what"])
    relabel = [
        f"* {v.claim.words}: {old[v.claim.id]} → **{v.label}** (" + "; ".join(o.text() for o in outs[v.claim.id]) + ")"
        for v in verdicts
    ]
    return {
        "runs": runs,
        "seeds": len(T["seeds"]),
        "k_printed": f"{kurtosis(2, 0.75):.2f}",
        "k_strong": f"{kurtosis(10, 0.1):.1f}",
        "plots": "\n".join(figs),
        "where": where_table,
        "pooled": pooled_table,
        "relabel": "\n".join(relabel),
        "replication": replication(evs, rng),
        "poor": poor(evs, rng),
        **small_tables(evs, best),
        **{f"n_{k}": f"{a} of {b}" for k, (a, b) in n.items()},
        **{f"t_{g}": sweep(evs, g, m) for g, m in T["sweeps"].items()},
    }


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Write ``docs/reproduction/003.md`` (``runs`` Monte Carlo runs per row: 100, quick 4)."""
    watch, runs, doc = Stopwatch(), runs or (4 if quick else 100), Path(doc or "docs/reproduction/003.md")
    with pool(workers()) as ex:
        evs = compute(plan() + tune_plan(min(T["tune"]["runs"], runs)), runs, seed, data_dir, ex, quiet)
        more, best = tuned_jobs(evs)
        evs |= compute(more, runs, seed, data_dir, ex, quiet)
    evid = evidence(evs)
    verdicts = decide(T["claims"], evid, seed=seed)
    command = f"replay reproduce 003 --runs {runs} --seed {seed}" + (" --quick" if quick else "")
    fields_ = fields(evs, best, runs, doc, verdicts, evid) | {"command": command}
    write_document(doc, render("003", fields_, verdicts) + footer(command, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
