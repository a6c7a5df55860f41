"""Paper 003 (weight-factor PF vs PF, UAV formation under glint noise, §4 Fig. 1–6) from its table.

``replay/papers/003.toml`` (:data:`T`, every key checked by :func:`load`) declares the rows (a filter and its
parameters), the settings (dataset and task parameters, N, rows; the pooled rows of a pooled setting run on
every seed offset of ``seeds``), the baselines' tuning grids, the evidence (run-by-run comparisons of two rows
of a setting, :data:`VALUES`), the claims with their rules (:mod:`.spec`) and the tables' layouts. This module
runs the evaluations (:func:`replay.run.evaluation.evaluate`, ``REPLAY_WORKERS`` processes), decides
(:func:`.rules.decide`) and fills ``replay/papers/003.md`` (:func:`.render.render`). A setting, row, ablation
or comparison is a TOML edit: a ``setting`` line, a ``[row]``, an ``[evidence]`` line, a ``[[claim]]`` (a new
sweep table: a ``[sweeps]`` entry and its ``${t_<table>}`` in the template). :func:`check` suits any paper.
"""

from pathlib import Path
from types import SimpleNamespace as Job

import numpy as np

from replay.run.evaluation import evaluate
from replay.scoring.significance import holm, t_interval

from . import spec
from .common5 import combine, commands, per_run, rmse_curve, rmse_figures, table
from .pool import pool, run_longest_first, workers
from .render import render, table as md
from .rules import TEST_NAMES, Comparison, decide, p_text, test_one
from .verdict import Stopwatch, footer, write_document

TOP = (
    "dataset seeds pooled_rows growth tune setting row grid sweeps evidence peak figure where poor distinct heads claim"
)
KEYS = {"row": ("filter name", "particles params"), "grid": ("row param values shared", "")}


def check(entry: dict, need: str, may: str, where: str) -> None:
    """Refuse ``entry`` (``ValueError`` naming ``where``) unless it has every key of ``need``, others of ``may``."""
    bad, missing = set(entry) - set(f"{need} {may}".split()), set(need.split()) - set(entry)
    if bad or missing:
        raise ValueError(
            f"003.toml: {where}: {f'unknown key(s) {sorted(bad)}' if bad else f'missing {sorted(missing)}'}"
        )


def load(t: dict) -> dict:
    """The parsed table, checked (:func:`check`; the rows, settings and values it names exist), with ``claims``
    (:func:`.spec.claims`) and ``by_label`` (the settings by label)."""
    check(t, TOP, "", "top level")
    for kind, k, e in [(kind, k, e) for kind in KEYS for k, e in t[kind].items()]:
        check(e, *KEYS[kind], f"{kind} {k!r}")
    for c in t["where"]["columns"]:
        check(c, "head a b family", "mcnemar", f"where column {c.get('head')!r}")
    by, rows = {s.get("label"): s for s in t["setting"]}, set(t["row"]) | {"zero"}
    for k, s in by.items():
        check(s, "label table n rows", "data task pooled", f"setting {k!r}")
        if set(s["rows"]) - rows or s["table"] not in t["sweeps"]:
            raise ValueError(f"003.toml: setting {k!r}: a row of {s['rows']} or its table {s['table']!r} is unknown")
    for k, v in t["evidence"].items():
        if any(len(c) != 5 or c[1] not in by or {c[2], c[3]} - rows or c[4] not in VALUES for c in v):
            raise ValueError(f"003.toml: evidence {k!r}: not [[name, setting, row a, row b, {'|'.join(VALUES)}], …]")
    return t | {"by_label": by, "claims": spec.claims(t, "003.toml")}


def growth(ev):
    """Per run: RMS position error over the steps ``growth.late`` minus over ``growth.early`` (NaN: diverged)."""
    res, (a, b), (c, d) = ev.results[0], T["growth"]["early"], T["growth"]["late"]
    e = np.linalg.norm(np.stack([np.asarray(x["position"], float) for x in res.errors]), axis=-1)
    e[[bool(r.get("diverged")) for r in res.runs]] = np.nan
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.mean(e[:, c:d] ** 2, axis=1)) - np.sqrt(np.mean(e[:, a:b] ** 2, axis=1))


def run_errors(ev, i=0) -> dict:
    """Per-run absolute position errors (runs, steps) of result ``i`` of ``ev``, per axis of ``figure.axes`` (m)."""
    pos = np.abs(np.stack([np.asarray(e["position"], float) for e in ev.results[i].errors]))
    return {key: pos[:, :, j] for j, (key, *_) in enumerate(T["figure"]["axes"])}


rmse = lambda ev: per_run(ev, 0, "pos_rmse")  # position RMSE per run (NaN: diverged)
lost = lambda ev: np.array([bool(r.get("lost")) for r in ev.results[0].runs])
distinct = lambda ev: np.array(
    [np.mean(getattr(e, "info", {}).get("distinct", np.nan)) for e in ev.results[0].estimates]
)
VALUES = {"rmse": rmse, "growth": growth, "distinct": distinct, "lost": lost}  # the per-run values [evidence] names
kurtosis = lambda r, eps: 3 * ((1 - eps) + eps * r**4) / ((1 - eps) + eps * r**2) ** 2 - 3  # of the glint, r = σ₂/σ₁
T = load(spec.load("003"))
name = lambda row: T["row"][row]["name"]


def row_job(key, s, row, tuned=None, seed=0, runs=0) -> Job:
    """The evaluation of ``row`` at setting ``s`` (seed offset ``seed``); ``tuned``: a grid's (parameter, value)."""
    f, r, data, task = T["row"][row]["filter"], T["row"][row], dict(s.get("data", {})), dict(s.get("task", {}))
    p = ({"n_particles": s["n"]} if r.get("particles") else {}) | r.get("params", {}) | dict([tuned] if tuned else [])
    return Job(key=key, filters=(f,), filter_params={f: p}, dataset_params=data, task_params=task, seed=seed, runs=runs)


def plan() -> list[Job]:
    """Every evaluation of the settings, keyed ``<label>|<row>|<seed offset>``."""
    seeds = lambda s, r: T["seeds"] if s.get("pooled") and r in T["pooled_rows"] else (0,)
    return [
        row_job(f"{s['label']}|{r}|{k}", s, r, seed=k) for s in T["setting"] for r in s["rows"] for k in seeds(s, r)
    ]


def tune_plan(runs: int = 0) -> list[Job]:
    """The grid evaluations on the tuning seeds, keyed ``tune|<setting>|<grid>|<value>``."""
    tu, cells = (
        T["tune"],
        [(s, g, d, v) for s in T["tune"]["settings"] for g, d in T["grid"].items() for v in d["values"]],
    )
    return [
        row_job(f"tune|{s}|{g}|{v}", T["by_label"][s], d["row"], (d["param"], v), tu["seed"], runs or tu["runs"])
        for s, g, d, v in cells
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
    peak = [
        Comparison(f"{x} at step {k[x] + 1} (m²)", err[x][:, k[x]] ** 2, target=v**2) for x, v in p["paper"].items()
    ]
    return {p["key"]: peak} | out


def cellof(o, p=None, digits=2) -> str:
    """An outcome in a table cell: the estimate, its interval, ``p`` (default its adjusted p); bold where it holds."""
    p = p_text(o.p_adj if p is None else p)
    if o.test == "mcnemar":
        return f"{int(np.sum(o.comparison.lost_a))} vs {int(np.sum(o.comparison.lost_b))}, p = {p}"
    s = f"{o.estimate:+.{digits}f} [{o.lo:+.{digits}f}, {o.hi:+.{digits}f}], p = {p}"
    return f"**{s}**" if o.holds else s


def family(outs, alpha=0.05) -> int:
    """Holm over ``outs`` (sets their p_adj and holds); how many hold."""
    for o, p in zip(outs, holm([o.p for o in outs])):
        o.p_adj, o.holds = float(p), bool(p < alpha)
    return sum(o.holds for o in outs)


def where(evs, rng) -> tuple[str, dict]:
    """``[where]``, every setting on seed s: each column's paired position-RMSE comparison (auto: paired t, or
    Wilcoxon and the median's bootstrap interval where a run is lost), the exact McNemar test of the lost runs
    of the ``mcnemar`` columns; Holm over each family. The table and {family: (significant, size)}."""
    w, fams, body = T["where"], {}, []
    for s in T["setting"]:
        ev = {r: evs[f"{s['label']}|{r}|0"] for r in s["rows"]}
        cmp = lambda c: Comparison(s["label"], *(f(ev[c[x]]) for f in (rmse, lost) for x in "ab"))
        o = [test_one(cmp(c), "auto", rng) if {c["a"], c["b"]} <= set(ev) else None for c in w["columns"]]
        mc = [test_one(x.comparison, "mcnemar", rng) for x, c in zip(o, w["columns"]) if x and c.get("mcnemar")]
        for x, f in [(x, c["family"]) for x, c in zip(o, w["columns"]) if x] + [(m, "lost") for m in mc]:
            fams.setdefault(f, []).append(x)
        body.append([s["label"], o, "/".join(str(int(lost(ev[r]).sum())) if r in ev else "–" for r in w["counts"]), mc])
    n = {k: (family(v), len(v)) for k, v in fams.items()}
    body = [[lab, *[cellof(x) if x else "n/a" for x in o], k, "; ".join(map(cellof, mc))] for lab, o, k, mc in body]
    return md(["setting", *[c["head"] for c in w["columns"]], *w["heads"]], body), n


def pooled(evs, evid, rng) -> tuple[str, dict, str]:
    """Every comparison of the verdicts (deciding, stated condition) on the pooled seeds, Holm over each claim's
    family as :func:`.rules.decide` adjusts it; {claim id: outcomes}; the replication: each but the peak on
    each seed alone (estimate [interval], raw p; not deciding)."""
    body, by, tests, rep = [], {}, {}, []
    for c in T["claims"]:
        keys = [k for k in (c.rule.decides, c.rule.condition) if k]
        tests |= {k: c.rule.test for k in keys}
        by[c.id] = outs = [test_one(x, c.rule.test, rng) for k in keys for x in evid[k]]
        family([o for o in outs if o.test != "interval"], c.rule.alpha)
        for i, o in enumerate(outs):
            text = o.text() if o.test == "interval" else f"{o.comparison.name}: {cellof(o)}"
            body.append(
                [c.id, "deciding" if i < len(evid[c.rule.decides]) else "stated condition", TEST_NAMES[o.test], text]
            )
    per = [evidence(evs, (k,)) for k in T["seeds"]]
    for key, test in tests.items():
        for i, c in enumerate(per[0][key] if key != T["peak"]["key"] else []):
            outs = [test_one(p[key][i], test, rng) for p in per]
            rep.append([key, c.name.split(": ", 1)[-1], *(cellof(o, o.p) for o in outs)])
    head = ["evidence", "comparison", *[f"seed s + {k}" for k in T["seeds"]]]
    return md(T["heads"]["pooled"], body), by, md(head, rep)


def sweep(evs, group, metrics) -> str:
    """One result table per setting of ``group`` (mean ± t, median, lost, paired Δ against α = 1), its commands."""
    rs = [
        combine([(f"{s['label']}: {name(r)}", (evs[f"{s['label']}|{r}|0"], 0)) for r in s["rows"]], metrics=metrics)
        for s in T["setting"]
        if s["table"] == group
    ]
    return "\n".join(
        f"{table(r, metrics=metrics, base_name='α = 1')}\n\nCommands (one per row):\n\n{commands(r)}\n" for r in rs
    )


def ci(x, digits=2, scale=1.0) -> str:
    m, h = t_interval(np.asarray(x, float) * scale)
    return f"{m:+.{digits}f} ± {h:.{digits}f}" if np.isfinite(h) else "n/a"


def small_tables(evs, best) -> dict:
    """The drift table (growth on the pooled seeds, peak of RMSE(t) on seed s), the distinct particles after
    resampling (% of N: mean over steps, then runs ± t; seed s), each baseline at its shared setting and tuned."""
    h, f = {k: [x.format(seeds=len(T["seeds"])) for x in v] for k, v in T["heads"].items()}, T["figure"]["setting"]
    peak = lambda r: " / ".join(f"{np.nanmax(rmse_curve(e)):.2f}" for e in run_errors(evs[f"{f}|{r}|0"]).values())
    grow = lambda r: ci(np.concatenate([growth(evs[f"{f}|{r}|{k}"]) for k in T["seeds"]]))
    dist = lambda s, r: (
        ci(distinct(evs[f"{s['label']}|{r}|0"]), 1, 100 / s["n"]).lstrip("+") if r in s["rows"] else "n/a"
    )
    row = lambda r: (
        f"{r['pos_rmse']:.2f} ± {r['pos_rmse_ci95']:.2f} (median {r['pos_rmse_median']:.2f}, lost {r['lost']})"
    )
    edge = lambda v, sc: " (grid edge)" if v in (min(sc), max(sc)) and len(sc) > 1 else ""
    tuned = []
    for (s, g), (v, sc) in best.items():
        grid = ", ".join(f"{x:g}: {y:.2f}" for x, y in sc.items())
        shared, ours = evs[f"{s}|{T['grid'][g]['shared']}|0"].rows[0], evs[f"tuned|{s}|{g}"].rows[0]
        tuned.append([s, g, T["grid"][g]["param"], grid, f"{v:g}{edge(v, sc)}", row(shared), row(ours)])
    return {
        "drift": md(h["drift"], [[name(r), peak(r), grow(r)] for r in T["figure"]["rows"]]),
        "distinct": md(
            h["distinct"], [[s["label"], s["n"], *(dist(s, r) for r in T["distinct"]["rows"])] for s in T["setting"]]
        ),
        "tuned": md(h["tuned"], tuned),
    }


def poor(evs, rng) -> str:
    """``[poor]``: the lost runs of each row (seed s) and of the tuned baselines, arm a against arm b on the
    pooled seeds (median Δ, lost runs), the distinct particles kept (not deciding)."""
    p, lab, s = T["poor"], T["poor"]["setting"], T["by_label"][T["poor"]["setting"]]
    get = lambda r, fn: np.concatenate([fn(evs[f"{lab}|{r}|{k}"]) for k in T["seeds"]])
    c = Comparison(p["name"], *(get(p[x], f) for f in (rmse, lost) for x in "ab"))
    o, m = test_one(c, "auto", rng), test_one(c, "mcnemar", rng)
    n = len(lost(evs[f"{lab}|{p['b']}|0"]))
    seed_s = ", ".join(f"{name(r)} {int(lost(evs[f'{lab}|{r}|0']).sum())}" for r in s["rows"])
    kept = ", ".join(f"α = {r[2:]}: {np.nanmean(get(r, distinct)):.1f}" for r in p["distinct"])
    tuned = ", ".join(f"{g} {evs[f'tuned|{lab}|{g}'].rows[0]['lost']}" for g in T["grid"])
    return (
        f"lost runs (of {n}) at seed s: {seed_s}; tuned: {tuned}. {p['name']}, {len(c.a)} "
        f"pooled runs: median Δ {cellof(o, o.p)}; lost {cellof(m, m.p)}. Distinct particles after resampling (of "
        f"N = {s['n']}, pooled): {kept}"
    )


def plots(t, errors: dict, doc: Path, what: str) -> list[str]:
    """Write ``003_rmse_<axis>.png`` beside ``doc`` (:func:`.common5.rmse_figures`, a panel per filter of
    ``errors`` = {label: :func:`run_errors`}); the Markdown lines that show them."""
    from replay.outputs.plots import save

    try:
        figs = rmse_figures(t, errors, T["figure"]["axes"], f"003, {what}")
    except ImportError:
        return ["(plot skipped: matplotlib is not installed)", ""]
    doc.parent.mkdir(parents=True, exist_ok=True)
    for key, q, _ in T["figure"]["axes"]:
        save(figs[key], doc.parent / f"003_rmse_{key}.png")
    return [x for k, q, _ in T["figure"]["axes"] for x in (f"![{q} over time, {what}](003_rmse_{k}.png)", "")] + [
        T["figure"]["caption"],
        "",
    ]


def fields(evs, best, runs, doc, verdicts, evid) -> dict:
    """Every placeholder of ``replay/papers/003.md`` but the verdicts and the command."""
    rng, f, old = np.random.default_rng(0), T["figure"], spec.old_labels(T)
    where_table, n = where(evs, rng)
    pooled_table, outs, replication = pooled(evs, evid, rng)
    ev = {name(r): evs[f"{f['setting']}|{r}|0"] for r in f["rows"]}
    figs = plots(next(iter(ev.values())).t, {k: run_errors(e) for k, e in ev.items()}, doc, f["what"])
    relabel = [
        f"* {v.claim.words}: {old[v.claim.id]} → **{v.label}** ({'; '.join(o.text() for o in outs[v.claim.id])})"
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
        "replication": replication,
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
    text = render("003", fields(evs, best, runs, doc, verdicts, evid) | {"command": command}, verdicts)
    write_document(doc, text + footer(command, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
