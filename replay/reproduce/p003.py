"""Paper 003 (weight-factor PF vs PF, UAV formation, glint noise; §4 Fig. 1–6) from ``replay/papers/003.toml``.

The table (:data:`T`, checked by :func:`load` against :data:`SCHEMA`) declares the rows (a filter, its parameters),
the settings (dataset and task parameters, N, rows; a pooled setting runs ``pooled_rows`` on every offset of
``seeds``), the tuning grids, the evidence (run-by-run comparisons of two rows by a value of :data:`VALUES`), the
claims and rules (:mod:`.spec`) and the layouts. :func:`run` evaluates (``REPLAY_WORKERS`` processes), decides
(:func:`.rules.decide`) and fills ``replay/papers/003.md``. A setting, row, ablation or comparison is a TOML edit
(``setting``, ``[row]``, ``[evidence]``, ``[[claim]]``; a new sweep table: ``[sweeps]`` and its ``${t_<table>}``).
"""

from pathlib import Path

import numpy as np

from replay.campaign.longest import Job, evaluate_jobs
from replay.filters.p003.wfpf import mean_distinct
from replay.outputs.plots import rmse_curve, rmse_figures, save
from replay.scoring.metrics import axis_errors, stacked_errors, window_growth
from replay.scoring.significance import t_interval
from replay.sim.uav_formation import glint_003
from replay.util.portable import write_document

from . import spec
from .render import render
from .render import table as md
from .rules import TEST_NAMES, Comparison, decide, holm_adjust, p_text, test_one
from .tables import Stopwatch, combine, commands, footer, mean_ci, per_run, table

SCHEMA = {  # the keys of each table of 003.toml ("key?": optional); row, grid, setting, column, kurtosis: of each entry
    "top level": "dataset seeds pooled_rows growth tune pooled_head setting row grid sweeps evidence peak drift "
    "distinct where poor kurtosis claim",
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
    "kurtosis": "ratio eps digits",
}


def load(t: dict) -> dict:
    """``t`` checked (:func:`.spec.check` against :data:`SCHEMA`; the rows, settings, tables and values named must
    be declared), with ``by_label``: the settings by label."""
    spec.check(t, SCHEMA["top level"], "003.toml: top level")
    entries = [(k, t[k], k) for k in ("growth", "tune", "peak", "drift", "distinct", "where", "poor")]
    entries += [(f"{kind} {k!r}", e, kind) for kind in ("row", "grid", "kurtosis") for k, e in t[kind].items()]
    entries += [(f"setting {s.get('label')!r}", s, "setting") for s in t["setting"]]
    entries += [(f"column {c.get('head')!r}", c, "column") for c in t["where"]["columns"]]
    for where, e, kind in entries:
        spec.check(e, SCHEMA[kind], f"003.toml: {where}")
    by, rows = {s["label"]: s for s in t["setting"]}, {*t["row"], "zero"}

    def declared(c):  # [name, setting, arm a, arm b, per-run value]
        return len(c) == 5 and c[1] in by and not {*c[2:4]} - rows and c[4] in VALUES

    bad = [f"setting {k!r}" for k, s in by.items() if set(s["rows"]) - rows or s["table"] not in t["sweeps"]]
    bad += [f"evidence {k!r}" for k, v in t["evidence"].items() if not all(map(declared, v))]
    if bad:
        raise ValueError(f"003.toml: {bad[0]}: names a row, setting, sweep table or per-run value not declared")
    return t | {"by_label": by}


def rmse(ev) -> np.ndarray:
    """Position RMSE per run (NaN: diverged)."""
    return per_run(ev, 0, "pos_rmse")


def lost(ev) -> np.ndarray:
    """Per run: the track was lost."""
    return np.array([bool(r.get("lost")) for r in ev.results[0].runs])


def growth(ev) -> np.ndarray:
    """Per run: RMS position error over the steps ``growth.late`` minus over ``growth.early`` (NaN: diverged)."""
    res, g = ev.results[0], T["growth"]
    diverged = [bool(r.get("diverged")) for r in res.runs]
    return window_growth(stacked_errors(res.errors), g["early"], g["late"], invalid=diverged)


def distinct(ev) -> np.ndarray:
    """Per run: the mean distinct particles after resampling (NaN: a filter that does not count them)."""
    return mean_distinct(ev.results[0].estimates)


VALUES = {"rmse": rmse, "growth": growth, "distinct": distinct, "lost": lost}  # the per-run values [evidence] names
T = load(spec.load("003"))
CLAIMS, OLD, SEEDS = spec.claims(T, "003.toml"), spec.old_labels(T), T["seeds"]
NAMES = {k: r["name"] for k, r in T["row"].items()}  # the rows' names in the tables


def run_errors(ev, i=0) -> dict:
    """Per-run absolute position errors (runs, steps) of result ``i`` of ``ev`` per axis of ``drift.axes`` (m)."""
    return axis_errors(ev.results[i].errors, [key for key, *_ in T["drift"]["axes"]])


def job(key, s, row, runs, seed=0, tuned=None) -> Job:
    """Evaluation ``key``: ``row`` at setting ``s``, ``runs`` runs, seed offset ``seed``, ``tuned`` = (param, value)."""
    r = T["row"][row]
    params = (
        ({"n_particles": s["n"]} if r.get("particles") else {}) | r.get("params", {}) | dict([tuned] if tuned else [])
    )
    data, task = dict(s.get("data", {})), dict(s.get("task", {}))
    return Job(key, T["dataset"], (r["filter"],), data, {r["filter"]: params}, task, runs=runs, seed=seed)


def plan(runs: int, tune_runs: int) -> list[Job]:
    """The settings' evaluations, ``<label>|<row>|<seed offset>`` (``runs`` each; a pooled row of a pooled setting
    on every offset of ``seeds``, the others on seed s), and the grids' on the tuning seeds,
    ``tune|<setting>|<grid>|<value>`` (``tune_runs`` each)."""
    jobs = []
    for s in T["setting"]:
        for r in s["rows"]:
            offsets = SEEDS if s.get("pooled") and r in T["pooled_rows"] else [0]
            jobs += [job(f"{s['label']}|{r}|{k}", s, r, runs, k) for k in offsets]
    for lab, (g, d) in [(lab, x) for lab in T["tune"]["settings"] for x in T["grid"].items()]:
        s, seed = T["by_label"][lab], T["tune"]["seed"]
        jobs += [job(f"tune|{lab}|{g}|{v}", s, d["row"], tune_runs, seed, (d["param"], v)) for v in d["values"]]
    return jobs


def seed_s(evs, lab: str, row: str):
    """The evaluation of ``row`` at setting ``lab`` on the document's seed s."""
    return evs[f"{lab}|{row}|0"]


def pooled_runs(evs, lab: str, row: str, value: str, seeds=SEEDS) -> np.ndarray:
    """The per-run ``value`` (:data:`VALUES`) of ``row`` at setting ``lab``, the runs of ``seeds`` one after another."""
    return np.concatenate([VALUES[value](evs[f"{lab}|{row}|{k}"]) for k in seeds])


def pair(evs, txt, lab, a, b, value, seeds=SEEDS) -> Comparison:
    """``a`` against ``b`` at setting ``lab``, run by run on ``seeds`` pooled: per-run ``value`` and lost flags
    (``a`` = ``zero``: 0 on every run)."""
    vb, lb = pooled_runs(evs, lab, b, value, seeds), pooled_runs(evs, lab, b, "lost", seeds)
    if a == "zero":
        return Comparison(txt, np.zeros_like(vb), vb, lb, lb)
    return Comparison(txt, pooled_runs(evs, lab, a, value, seeds), vb, pooled_runs(evs, lab, a, "lost", seeds), lb)


def evidence(evs, seeds=SEEDS) -> dict:
    """``[peak]``: RMSE(t)² at the peak of RMSE(t) (the paper's eq. 33 curve) per axis, seed s, against the paper's
    number squared; and ``[evidence]`` as ``key -> [Comparison]`` (:func:`pair`)."""
    p, peaks = T["peak"], []
    err = run_errors(seed_s(evs, p["setting"], p["row"]))
    for x, v in p["paper"].items():
        k = int(np.nanargmax(rmse_curve(err[x])))
        peaks.append(Comparison(f"{x} at step {k + 1} (m²)", err[x][:, k] ** 2, target=v**2))
    return {p["key"]: peaks} | {k: [pair(evs, *c, seeds) for c in v] for k, v in T["evidence"].items()}


def cell(o, p=None) -> str:
    """An outcome in a table cell: the estimate, its interval, ``p`` (default the adjusted p); bold where it holds
    (McNemar: the lost runs of both arms)."""
    p = p_text(o.p_adj if p is None else p)
    if o.test == "mcnemar":
        return f"{int(np.sum(o.comparison.lost_a))} vs {int(np.sum(o.comparison.lost_b))}, p = {p}"
    s = f"{o.estimate:+.2f} [{o.lo:+.2f}, {o.hi:+.2f}], p = {p}"
    return f"**{s}**" if o.holds else s


def ci(x, digits=2, scale=1.0) -> str:
    """Mean ± 95 % t half-width of ``x`` × ``scale`` (``n/a`` without a half-width)."""
    m, h = t_interval(np.asarray(x, float) * scale)
    return f"{m:+.{digits}f} ± {h:.{digits}f}" if np.isfinite(h) else "n/a"


def where(evs, rng) -> dict:
    """``where``: every setting on seed s, each column's paired position-RMSE comparison (paired t, or Wilcoxon and
    the median's bootstrap interval where a run is lost), exact McNemar on the lost runs of the ``mcnemar``
    columns, Holm over each family; ``n_<family>``: how many of the family hold."""
    w, fams, per_setting = T["where"], {}, []
    for s in T["setting"]:
        lab, cols = s["label"], [c for c in w["columns"] if c["a"] in s["rows"] and c["b"] in s["rows"]]
        o = {c["head"]: test_one(pair(evs, lab, lab, c["a"], c["b"], "rmse", (0,)), "auto", rng) for c in cols}
        mc = [test_one(o[c["head"]].comparison, "mcnemar", rng) for c in cols if c.get("mcnemar")]
        for x, f in [(o[c["head"]], c["family"]) for c in cols] + [(m, "lost") for m in mc]:
            fams.setdefault(f, []).append(x)
        counts = "/".join(str(lost(seed_s(evs, lab, r)).sum()) if r in s["rows"] else "–" for r in w["counts"])
        per_setting.append((lab, o, counts, mc))
    n = {f"n_{k}": f"{holm_adjust(v)} of {len(v)}" for k, v in fams.items()}  # before the cells: they show p_adj
    heads = [c["head"] for c in w["columns"]]
    rows = [
        [lab, *(cell(o[h]) if h in o else "n/a" for h in heads), k, "; ".join(map(cell, mc))]
        for lab, o, k, mc in per_setting
    ]
    return n | {"where": md(["setting", *heads, *w["heads"]], rows)}


def pooled(evs, evid, rng) -> dict:
    """``pooled``: the verdicts' comparisons on the pooled seeds, Holm over each claim's family as
    :func:`.rules.decide` adjusts it (``outs``: by claim); ``replication``: each but the peak on each seed alone."""
    rows, outs, tests, rep = [], {}, {}, []
    for c in CLAIMS:
        keys = [k for k in (c.rule.decides, c.rule.condition) if k]
        tests |= {k: c.rule.test for k in keys}
        outs[c.id] = [test_one(x, c.rule.test, rng) for k in keys for x in evid[k]]
        holm_adjust([o for o in outs[c.id] if o.test != "interval"], c.rule.alpha)
        for i, o in enumerate(outs[c.id]):
            role = "stated condition" if i >= len(evid[c.rule.decides]) else "deciding"
            text = o.text() if o.test == "interval" else f"{o.comparison.name}: {cell(o)}"
            rows.append([c.id, role, TEST_NAMES[o.test], text])
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
    o, m, runs_s = test_one(c, "auto", rng), test_one(c, "mcnemar", rng), len(lost(seed_s(evs, lab, p["b"])))
    kept = ", ".join(f"α = {r[2:]}: {np.nanmean(pooled_runs(evs, lab, r, 'distinct')):.1f}" for r in p["distinct"])
    at_s = ", ".join(f"{NAMES[r]} {lost(seed_s(evs, lab, r)).sum()}" for r in s["rows"])
    tuned = ", ".join(f"{g} {evs[f'tuned|{lab}|{g}'].rows[0]['lost']}" for g in T["grid"])
    return {
        "poor": f"lost runs (of {runs_s}) at seed s: {at_s}; tuned: {tuned}. {p['name']}, {len(c.a)} pooled runs: "
        f"median Δ {cell(o, o.p)}; lost {cell(m, m.p)}. Distinct particles after resampling (of N = {s['n']}, "
        f"pooled): {kept}"
    }


def tables(evs, best) -> dict:
    """The sweep tables ``t_<table>`` (per setting: mean ± t, median, lost, paired Δ against α = 1, commands), the
    distinct particles after resampling (% of N: mean over steps, then runs ± t; seed s), each baseline at its
    shared setting and tuned (``best``: (setting, grid) -> (value chosen, {value: tuning RMSE}))."""
    out, tuned = {f"t_{g}": [] for g in T["sweeps"]}, []

    def leaderboard(row: dict) -> str:  # mean ± 95 % position RMSE, median, lost
        return f"{mean_ci(row, 'pos_rmse', 2)} (median {row['pos_rmse_median']:.2f}, lost {row['lost']})"

    for s in T["setting"]:
        m = T["sweeps"][s["table"]]
        rs = combine([(f"{s['label']}: {NAMES[r]}", (seed_s(evs, s["label"], r), 0)) for r in s["rows"]], metrics=m)
        out[f"t_{s['table']}"].append(
            f"{table(rs, m, base_name='α = 1')}\n\nCommands (one per row):\n\n{commands(rs)}\n"
        )
    for (lab, g), (v, sc) in best.items():
        edge = " (grid edge)" if v in (min(sc), max(sc)) and len(sc) > 1 else ""
        shared, ours = seed_s(evs, lab, T["grid"][g]["shared"]).rows[0], evs[f"tuned|{lab}|{g}"].rows[0]
        grid = ", ".join(f"{x:g}: {y:.2f}" for x, y in sc.items())
        tuned.append([lab, g, T["grid"][g]["param"], grid, f"{v:g}{edge}", leaderboard(shared), leaderboard(ours)])

    def kept(s, r):  # % of N
        return ci(distinct(seed_s(evs, s["label"], r)), 1, 100 / s["n"]).lstrip("+") if r in s["rows"] else "n/a"

    dists = [[s["label"], s["n"], *(kept(s, r) for r in T["distinct"]["rows"])] for s in T["setting"]]
    out = {k: "\n".join(v) for k, v in out.items()}
    return out | {"distinct": md(T["distinct"]["head"], dists), "tuned": md(T["tune"]["head"], tuned)}


def drift(evs, doc: Path) -> dict:
    """The drift table (peak of RMSE(t) per axis on seed s, growth on the pooled seeds) and the figures
    ``003_rmse_<axis>.png`` beside ``doc`` (``plots``: their Markdown)."""
    d = T["drift"]
    errors = {r: run_errors(seed_s(evs, d["setting"], r)) for r in d["rows"]}
    peaks = {r: " / ".join(f"{np.nanmax(rmse_curve(x)):.2f}" for x in e.values()) for r, e in errors.items()}
    rows = [[NAMES[r], peaks[r], ci(pooled_runs(evs, d["setting"], r, "growth"))] for r in d["rows"]]
    t = seed_s(evs, d["setting"], d["rows"][0]).t
    figs = rmse_figures(t, {NAMES[r]: e for r, e in errors.items()}, d["axes"], f"003, {d['what']}")
    doc.parent.mkdir(parents=True, exist_ok=True)
    plots = []
    for k, q, _ in d["axes"]:
        save(figs[k], doc.parent / f"003_rmse_{k}.png")
        plots += [f"![{q} over time, {d['what']}](003_rmse_{k}.png)", ""]
    head = [h.format(seeds=len(SEEDS)) for h in d["head"]]
    return {"drift": md(head, rows), "plots": "\n".join([*plots, d["caption"], ""])}


def tune(evs, runs: int) -> tuple[dict, list[Job]]:
    """Each baseline's grid value with the lowest mean position RMSE on the tuning seeds, ``(setting, grid) ->
    (value, {value: RMSE})``, and the jobs ``tuned|<setting>|<grid>`` that run it on seed s."""
    best, jobs = {}, []
    for lab, (g, d) in [(lab, x) for lab in T["tune"]["settings"] for x in T["grid"].items()]:
        sc = {v: float(evs[f"tune|{lab}|{g}|{v}"].rows[0]["pos_rmse"]) for v in d["values"]}
        v = d["values"][int(np.nanargmin(list(sc.values())))]
        best[(lab, g)] = v, sc
        jobs.append(job(f"tuned|{lab}|{g}", T["by_label"][lab], d["row"], runs, 0, (d["param"], v)))
    return best, jobs


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Write ``docs/reproduction/003.md`` (``runs`` Monte Carlo runs per row: 100, quick 4); each baseline at its
    grid's best (:func:`tune`)."""
    watch, runs, doc = Stopwatch(), runs or (4 if quick else 100), Path(doc or "docs/reproduction/003.md")
    evs = evaluate_jobs(plan(runs, min(T["tune"]["runs"], runs)), runs, seed, data_dir, quiet, "003: ")
    best, more = tune(evs, runs)
    evs |= evaluate_jobs(more, runs, seed, data_dir, quiet, "003: ")
    evid, rng = evidence(evs), np.random.default_rng(0)
    verdicts = decide(CLAIMS, evid, seed=seed)
    command = f"replay reproduce 003 --runs {runs} --seed {seed}" + (" --quick" if quick else "")
    f = where(evs, rng) | pooled(evs, evid, rng) | poor(evs, rng) | tables(evs, best) | drift(evs, doc)
    outs = f.pop("outs")
    relabel = [
        f"* {v.claim.words}: {OLD[v.claim.id]} → **{v.label}** ({'; '.join(o.text() for o in outs[v.claim.id])})"
        for v in verdicts
    ]
    f |= {"runs": runs, "seeds": len(SEEDS), "command": command, "relabel": "\n".join(relabel)}
    for k, g in T["kurtosis"].items():  # of the simulator's glint bearing noise (σ₁ = 1, σ₂ = ratio)
        f[k] = f"{glint_003(g['eps'], 1.0, 1.0, g['ratio']).excess_kurtosis()[1]:.{g['digits']}f}"
    write_document(doc, render("003", f, verdicts) + footer(command, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
