"""Paper 003 (weight-factor PF vs PF, UAV formation, glint noise; §4 Fig. 1–6) from ``replay/papers/003.toml``.

The table (:data:`T`, checked by :func:`load` against :data:`SCHEMA`) declares the rows (a filter, its parameters),
the settings (dataset and task parameters, N, rows; a pooled setting runs ``pooled_rows`` on every offset of
``seeds``), the tuning grids, the evidence (run-by-run comparisons of two rows by a value of :data:`VALUES`), the
claims and rules (:mod:`.spec`) and the layouts. :func:`run` evaluates (``REPLAY_WORKERS`` processes), decides
(:func:`.rules.decide`) and fills ``replay/papers/003.md``. A setting, row, ablation or comparison is a TOML edit
(``setting``, ``[row]``, ``[evidence]``, ``[[claim]]``; a new sweep table: ``[sweeps]`` and its ``${t_<table>}``).
"""

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from replay.campaign.longest import pool, run_longest_first, workers
from replay.outputs.plots import rmse_curve, rmse_figures, save
from replay.run.evaluation import evaluate
from replay.scoring.significance import holm, t_interval
from replay.util.portable import write_document

from . import spec
from .render import render
from .render import table as md
from .rules import TEST_NAMES, Comparison, decide, p_text, test_one
from .tables import Stopwatch, combine, commands, footer, per_run, table

SCHEMA = {  # the keys of each table of 003.toml ("key?": optional); row, grid, setting, column: of each entry
    "top level": "dataset seeds pooled_rows growth tune pooled_head setting row grid sweeps evidence peak drift "
    "distinct where poor claim",
    "growth": "early late",
    "tune": "seed runs settings head",
    "peak": "key setting row paper",
    "drift": "setting rows head what axes caption",
    "distinct": "rows head",
    "where": "columns counts heads",
    "poor": "setting name a b distinct",
    "row": "filter name particles? params?",
    "grid": "row param values shared",
    "setting": "label table n rows data? task? pooled?",
    "column": "head a b family mcnemar?",
}


def check(where: str, entry: dict, keys: str) -> None:
    """Refuse (naming the file and ``where``) an ``entry`` without every key of ``keys`` or with another key."""
    spec.check(entry, keys, f"003.toml: {where}")


def load(t: dict) -> dict:
    """``t`` checked (:func:`check` against :data:`SCHEMA`; the rows, settings, tables and values named must be
    declared), with ``by_label``: the settings by label."""
    check("top level", t, SCHEMA["top level"])
    entries = [(k, t[k], k) for k in ("growth", "tune", "peak", "drift", "distinct", "where", "poor")]
    entries += [(f"{kind} {k!r}", e, kind) for kind in ("row", "grid") for k, e in t[kind].items()]
    entries += [(f"setting {s.get('label')!r}", s, "setting") for s in t["setting"]]
    for where, e, kind in entries:
        check(where, e, SCHEMA[kind])
    for c in t["where"]["columns"]:
        check(f"column {c.get('head')!r}", c, SCHEMA["column"])
    by, rows = {s["label"]: s for s in t["setting"]}, {*t["row"], "zero"}
    ok = lambda c: len(c) == 5 and c[1] in by and not {*c[2:4]} - rows and c[4] in VALUES
    bad = [f"setting {k!r}" for k, s in by.items() if set(s["rows"]) - rows or s["table"] not in t["sweeps"]]
    bad += [f"evidence {k!r}" for k, v in t["evidence"].items() if not all(map(ok, v))]
    if bad:
        raise ValueError(f"003.toml: {bad[0]}: names a row, setting, sweep table or per-run value not declared")
    return t | {"by_label": by}


@np.errstate(invalid="ignore")
def growth(ev):
    """Per run: RMS position error over the steps ``growth.late`` minus over ``growth.early`` (NaN: diverged)."""
    res, (a, b), (c, d) = ev.results[0], T["growth"]["early"], T["growth"]["late"]
    e = np.linalg.norm(np.stack([np.asarray(x["position"], float) for x in res.errors]), axis=-1)
    e[[bool(r.get("diverged")) for r in res.runs]] = np.nan
    return np.sqrt(np.mean(e[:, c:d] ** 2, axis=1)) - np.sqrt(np.mean(e[:, a:b] ** 2, axis=1))


def run_errors(ev, i=0) -> dict:
    """Per-run absolute position errors (runs, steps) of result ``i`` of ``ev`` per axis of ``drift.axes`` (m)."""
    pos = np.abs(np.stack([np.asarray(e["position"], float) for e in ev.results[i].errors]))
    return {key: pos[:, :, j] for j, (key, *_) in enumerate(T["drift"]["axes"])}


rmse = lambda ev: per_run(ev, 0, "pos_rmse")  # position RMSE per run (NaN: diverged)
lost = lambda ev: np.array([bool(r.get("lost")) for r in ev.results[0].runs])
info = lambda e: getattr(e, "info", {})  # an estimate's filter record (none for a run without one)
distinct = lambda ev: np.array([np.mean(info(e).get("distinct", np.nan)) for e in ev.results[0].estimates])
VALUES = {"rmse": rmse, "growth": growth, "distinct": distinct, "lost": lost}  # the per-run values [evidence] names
kurtosis = lambda r, eps: 3 * ((1 - eps) + eps * r**4) / ((1 - eps) + eps * r**2) ** 2 - 3  # of the glint, r = σ₂/σ₁
T = load(spec.load("003"))
CLAIMS, OLD, SEEDS = spec.claims(T, "003.toml"), spec.old_labels(T), T["seeds"]
name = lambda row: T["row"][row]["name"]


def job(key, s, row, runs, seed=0, tuned=None) -> SimpleNamespace:
    """Evaluation ``key``: ``row`` at setting ``s``, ``runs`` runs, seed offset ``seed``, ``tuned`` = (param, value)."""
    f, r, data, task = T["row"][row]["filter"], T["row"][row], dict(s.get("data", {})), dict(s.get("task", {}))
    p = ({"n_particles": s["n"]} if r.get("particles") else {}) | r.get("params", {}) | dict([tuned] if tuned else [])
    kw = dict(filters=(f,), filter_params={f: p}, dataset_params=data, task_params=task)
    return SimpleNamespace(key=key, seed=seed, runs=runs, **kw)


def plan(runs: int, tune_runs: int) -> list[SimpleNamespace]:
    """The settings' evaluations, ``<label>|<row>|<seed offset>`` (``runs`` each), and the grids' on the tuning
    seeds, ``tune|<setting>|<grid>|<value>`` (``tune_runs`` each)."""
    tu, ks = T["tune"], lambda s, r: SEEDS if s.get("pooled") and r in T["pooled_rows"] else (0,)
    jobs = [job(f"{s['label']}|{r}|{k}", s, r, runs, k) for s in T["setting"] for r in s["rows"] for k in ks(s, r)]
    cells = [(s, g, d, v) for s in tu["settings"] for g, d in T["grid"].items() for v in d["values"]]
    tune = lambda s, g, d, v: job(
        f"tune|{s}|{g}|{v}", T["by_label"][s], d["row"], tune_runs, tu["seed"], (d["param"], v)
    )
    return jobs + [tune(*c) for c in cells]


def _evaluate(args):
    j, seed, data_dir = args
    kw = dict(dataset_params=j.dataset_params or None, filter_params=j.filter_params, task_params=j.task_params or None)
    return evaluate(T["dataset"], filters=j.filters, runs=j.runs, seed=seed + j.seed, data_dir=data_dir, **kw)


def compute(jobs, seed, data_dir, ex, quiet) -> dict:
    """``{key: Evaluation}`` of ``jobs``, the costliest first."""
    cost = [j.runs * sum(p.get("n_particles", 30) for p in j.filter_params.values()) for j in jobs]
    args, labels = [(j, seed, data_dir) for j in jobs], [f"{j.key} ({j.runs} runs)" for j in jobs]
    return {jobs[i].key: ev for i, ev in run_longest_first(_evaluate, args, cost, labels, ex, quiet, "003: ")}


def pair(evs, txt, lab, a, b, value, seeds=SEEDS) -> Comparison:
    """``a`` against ``b`` at setting ``lab``: per-run ``value`` and lost flags on ``seeds`` pooled (``zero``: 0)."""
    get = lambda r, v: np.concatenate([VALUES[v](evs[f"{lab}|{r}|{k}"]) for k in seeds])
    vb, lb = get(b, value), get(b, "lost")
    va, la = (np.zeros_like(vb), lb) if a == "zero" else (get(a, value), get(a, "lost"))
    return Comparison(txt, va, vb, la, lb)


def evidence(evs, seeds=SEEDS) -> dict:
    """``[evidence]`` as ``key -> [Comparison]`` (:func:`pair`), and ``[peak]``: RMSE(t)² at the peak of RMSE(t)
    (the paper's eq. 33 curve) per axis, seed s, against the paper's number squared."""
    p, out = T["peak"], {k: [pair(evs, *c, seeds) for c in v] for k, v in T["evidence"].items()}
    err = run_errors(evs[f"{p['setting']}|{p['row']}|0"])
    k = {x: int(np.nanargmax(rmse_curve(err[x]))) for x in p["paper"]}
    peak = lambda x, v: Comparison(f"{x} at step {k[x] + 1} (m²)", err[x][:, k[x]] ** 2, target=v**2)
    return {p["key"]: [peak(x, v) for x, v in p["paper"].items()]} | out


def cell(o, p=None, digits=2) -> str:
    """An outcome in a table cell: the estimate, its interval, ``p`` (default the adjusted p); bold where it holds."""
    p = p_text(o.p_adj if p is None else p)
    if o.test == "mcnemar":
        return f"{int(np.sum(o.comparison.lost_a))} vs {int(np.sum(o.comparison.lost_b))}, p = {p}"
    s = f"{o.estimate:+.{digits}f} [{o.lo:+.{digits}f}, {o.hi:+.{digits}f}], p = {p}"
    return f"**{s}**" if o.holds else s


def holm_family(outs, alpha=0.05) -> int:
    """Holm over ``outs`` (sets their p_adj and holds); how many hold."""
    for o, p in zip(outs, holm([o.p for o in outs])):
        o.p_adj, o.holds = float(p), bool(p < alpha)
    return sum(o.holds for o in outs)


def ci(x, digits=2, scale=1.0) -> str:
    m, h = t_interval(np.asarray(x, float) * scale)
    return f"{m:+.{digits}f} ± {h:.{digits}f}" if np.isfinite(h) else "n/a"


def where(evs, rng) -> dict:
    """``where``: every setting on seed s, each column's paired position-RMSE comparison (paired t, or Wilcoxon and
    the median's bootstrap interval where a run is lost), exact McNemar on the lost runs of the ``mcnemar``
    columns, Holm over each family; ``n_<family>``: how many of the family hold."""
    w, fams, rows = T["where"], {}, []
    for s in T["setting"]:
        lab, cols = s["label"], [c for c in w["columns"] if c["a"] in s["rows"] and c["b"] in s["rows"]]
        o = {c["head"]: test_one(pair(evs, lab, lab, c["a"], c["b"], "rmse", (0,)), "auto", rng) for c in cols}
        mc = [test_one(o[c["head"]].comparison, "mcnemar", rng) for c in cols if c.get("mcnemar")]
        for x, f in [(o[c["head"]], c["family"]) for c in cols] + [(m, "lost") for m in mc]:
            fams.setdefault(f, []).append(x)
        counts = "/".join(str(int(lost(evs[f"{lab}|{r}|0"]).sum())) if r in s["rows"] else "–" for r in w["counts"])
        rows.append([lab, o, counts, mc])
    n = {f"n_{k}": f"{holm_family(v)} of {len(v)}" for k, v in fams.items()}
    cells = lambda o: [cell(o[c["head"]]) if c["head"] in o else "n/a" for c in w["columns"]]
    rows = [[lab, *cells(o), k, "; ".join(map(cell, mc))] for lab, o, k, mc in rows]
    return n | {"where": md(["setting", *[c["head"] for c in w["columns"]], *w["heads"]], rows)}


def pooled(evs, evid, rng) -> dict:
    """``pooled``: the verdicts' comparisons on the pooled seeds, Holm over each claim's family as
    :func:`.rules.decide` adjusts it (``outs``: by claim); ``replication``: each but the peak on each seed alone."""
    rows, outs, tests, rep = [], {}, {}, []
    for c in CLAIMS:
        keys = [k for k in (c.rule.decides, c.rule.condition) if k]
        tests |= {k: c.rule.test for k in keys}
        outs[c.id] = [test_one(x, c.rule.test, rng) for k in keys for x in evid[k]]
        holm_family([o for o in outs[c.id] if o.test != "interval"], c.rule.alpha)
        for i, o in enumerate(outs[c.id]):
            text = o.text() if o.test == "interval" else f"{o.comparison.name}: {cell(o)}"
            rows.append(
                [c.id, "stated condition" if i >= len(evid[c.rule.decides]) else "deciding", TEST_NAMES[o.test], text]
            )
    per = [evidence(evs, (k,)) for k in SEEDS]
    for key, test in tests.items():
        for i, c in enumerate(per[0][key] if key != T["peak"]["key"] else []):
            outs_k = [test_one(p[key][i], test, rng) for p in per]
            rep.append([key, c.name.split(": ", 1)[-1], *(cell(o, o.p) for o in outs_k)])
    head = ["evidence", "comparison", *[f"seed s + {k}" for k in SEEDS]]
    return {"pooled": md(T["pooled_head"], rows), "outs": outs, "replication": md(head, rep)}


def poor(evs, rng) -> dict:
    """``poor``: lost runs per row (seed s) and of the tuned baselines, arm a against arm b on the pooled seeds
    (median Δ, McNemar), the distinct particles kept (not deciding)."""
    p, lab, s = T["poor"], T["poor"]["setting"], T["by_label"][T["poor"]["setting"]]
    c = pair(evs, p["name"], lab, p["a"], p["b"], "rmse")
    o, m, n = test_one(c, "auto", rng), test_one(c, "mcnemar", rng), len(lost(evs[f"{lab}|{p['b']}|0"]))
    kept = ", ".join(f"α = {r[2:]}: {np.nanmean(pair(evs, '', lab, r, r, 'distinct').a):.1f}" for r in p["distinct"])
    seed_s = ", ".join(f"{name(r)} {int(lost(evs[f'{lab}|{r}|0']).sum())}" for r in s["rows"])
    tuned = ", ".join(f"{g} {evs[f'tuned|{lab}|{g}'].rows[0]['lost']}" for g in T["grid"])
    return {
        "poor": f"lost runs (of {n}) at seed s: {seed_s}; tuned: {tuned}. {p['name']}, {len(c.a)} pooled runs: "
        f"median Δ {cell(o, o.p)}; lost {cell(m, m.p)}. Distinct particles after resampling (of N = {s['n']}, "
        f"pooled): {kept}"
    }


def tables(evs, best, doc) -> dict:
    """The sweep tables (per setting: mean ± t, median, lost, paired Δ against α = 1, commands), the drift table and
    figures (``003_rmse_<axis>.png`` beside ``doc``), the distinct particles after resampling (% of N: mean over
    steps, then runs ± t; seed s), each baseline at its shared setting and tuned."""
    d, ev0, out, tuned = T["drift"], lambda lab, r: evs[f"{lab}|{r}|0"], {}, []
    peak = lambda r: " / ".join(f"{np.nanmax(rmse_curve(e)):.2f}" for e in run_errors(ev0(d["setting"], r)).values())
    grow = lambda r: ci(pair(evs, "", d["setting"], r, r, "growth").a)
    dist = lambda s, r: ci(distinct(ev0(s["label"], r)), 1, 100 / s["n"]).lstrip("+") if r in s["rows"] else "n/a"
    row = lambda r: (
        f"{r['pos_rmse']:.2f} ± {r['pos_rmse_ci95']:.2f} (median {r['pos_rmse_median']:.2f}, lost {r['lost']})"
    )
    for (s, g), (v, sc) in best.items():
        edge = " (grid edge)" if v in (min(sc), max(sc)) and len(sc) > 1 else ""
        grid, shared = ", ".join(f"{x:g}: {y:.2f}" for x, y in sc.items()), ev0(s, T["grid"][g]["shared"]).rows[0]
        ours = row(evs[f"tuned|{s}|{g}"].rows[0])
        tuned.append([s, g, T["grid"][g]["param"], grid, f"{v:g}{edge}", row(shared), ours])
    for g, m in T["sweeps"].items():
        for s in [s for s in T["setting"] if s["table"] == g]:
            rs = combine([(f"{s['label']}: {name(r)}", (ev0(s["label"], r), 0)) for r in s["rows"]], metrics=m)
            text = f"{table(rs, m, base_name='α = 1')}\n\nCommands (one per row):\n\n{commands(rs)}\n"
            out[f"t_{g}"] = out.get(f"t_{g}", []) + [text]
    errors = {name(r): run_errors(ev0(d["setting"], r)) for r in d["rows"]}
    figs = rmse_figures(ev0(d["setting"], d["rows"][0]).t, errors, d["axes"], f"003, {d['what']}")
    doc.parent.mkdir(parents=True, exist_ok=True)
    for k, q, _ in d["axes"]:
        save(figs[k], doc.parent / f"003_rmse_{k}.png")
        out["plots"] = out.get("plots", []) + [f"![{q} over time, {d['what']}](003_rmse_{k}.png)", ""]
    out["plots"] += [d["caption"], ""]
    out["drift"] = md([h.format(seeds=len(SEEDS)) for h in d["head"]], [[name(r), peak(r), grow(r)] for r in d["rows"]])
    dists = [[s["label"], s["n"], *(dist(s, r) for r in T["distinct"]["rows"])] for s in T["setting"]]
    out |= {"distinct": md(T["distinct"]["head"], dists), "tuned": md(T["tune"]["head"], tuned)}
    return {k: "\n".join(v) if isinstance(v, list) else v for k, v in out.items()}


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Write ``docs/reproduction/003.md`` (``runs`` Monte Carlo runs per row: 100, quick 4); each baseline at its
    grid's best (lowest mean position RMSE on the tuning seeds) runs as ``tuned|<setting>|<grid>``."""
    watch, runs, doc, best = Stopwatch(), runs or (4 if quick else 100), Path(doc or "docs/reproduction/003.md"), {}
    with pool(workers()) as ex:
        evs = compute(plan(runs, min(T["tune"]["runs"], runs)), seed, data_dir, ex, quiet)
        more = []
        for s, (g, d) in [(s, x) for s in T["tune"]["settings"] for x in T["grid"].items()]:
            sc = {v: float(evs[f"tune|{s}|{g}|{v}"].rows[0]["pos_rmse"]) for v in d["values"]}
            v = d["values"][int(np.nanargmin(list(sc.values())))]
            best[(s, g)] = v, sc
            more.append(job(f"tuned|{s}|{g}", T["by_label"][s], d["row"], runs, 0, (d["param"], v)))
        evs |= compute(more, seed, data_dir, ex, quiet)
    evid, rng = evidence(evs), np.random.default_rng(0)
    verdicts = decide(CLAIMS, evid, seed=seed)
    command = f"replay reproduce 003 --runs {runs} --seed {seed}" + (" --quick" if quick else "")
    f = where(evs, rng) | pooled(evs, evid, rng) | poor(evs, rng) | tables(evs, best, doc)
    outs = f.pop("outs")
    found = lambda v: "; ".join(o.text() for o in outs[v.claim.id])
    relabel = [f"* {v.claim.words}: {OLD[v.claim.id]} → **{v.label}** ({found(v)})" for v in verdicts]
    f |= {"runs": runs, "seeds": len(SEEDS), "command": command, "relabel": "\n".join(relabel)}
    f |= {"k_printed": f"{kurtosis(2, 0.75):.2f}", "k_strong": f"{kurtosis(10, 0.1):.1f}"}
    write_document(doc, render("003", f, verdicts) + footer(command, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
