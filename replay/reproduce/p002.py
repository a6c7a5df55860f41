"""``replay reproduce 002``: the IGWO-STCPF paper (UNGM, sonar Tables 5/6, Figs. 17/18, Bohai) as data.

``replay/papers/002.toml`` declares the experiments, the comparisons and the claims (its comments define every
key, :func:`load` checks them): a row, an ablation, a comparison or a claim is a TOML edit (a new experiment
also needs its ``${key}`` in ``replay/papers/002.md``). Each row is a filter of one ``replay eval`` call
(:func:`replay.run.evaluation.evaluate`); one experiment's rows share the seed, so they are paired by run.
"""

import json
import os
from collections import Counter
from functools import partial

import numpy as np

from replay.campaign.longest import pool, run_longest_first, workers
from replay.data import registry
from replay.filters.p002 import pso, swarm_kernels
from replay.run.eval_options import EvalOptions
from replay.run.evaluation import evaluate
from replay.run.manifest import command_line
from replay.scoring.metrics import share_above
from replay.scoring.significance import t_interval
from replay.util.portable import write_document

from . import spec
from .render import anchor_tag, render, table
from .rules import Comparison, decide, per_run, undecidable
from .tables import Stopwatch, footer, mean_ci

# The keys of each kind of entry of 002.toml ("key?": optional; [defaults] may give an optional key's default).
KEYS = dict(exp="key task rows dataset? dp? cols? tune? runs? first? per_sequence? last?", evidence="exps compare")
KEYS |= dict(row="label filter? params? paper? dp? tp?", compare="a b? target? col? lost? test?")
MEAN3 = "mean Euclidean error (m)"  # the column beside the RMSE: mean over steps of |e_k| (3-D in sonar and Bohai)
TOP = "grid columns runs quick above sequences tune_seq no_sequences commands defaults exp evidence claim"


def load() -> dict:
    """``replay/papers/002.toml``, every key checked (an entry gets the [defaults] of its kind), the rows completed."""
    t = spec.check(spec.load("002"), TOP, "002.toml: top level")
    entry = lambda raw, kind, where: t["defaults"].get(kind, {}) | spec.check(raw, KEYS[kind], f"002.toml: {where}")
    for kind, d in spec.check(t["defaults"], "exp? row? compare?", "002.toml: [defaults]").items():
        spec.check(d, " ".join(k for k in KEYS[kind].split() if k.endswith("?")), f"002.toml: [defaults] {kind}")
    for i, raw in enumerate(t["exp"]):
        e = t["exp"][i] = entry(raw, "exp", f"exp {i + 1}")
        for part in ("rows", "last"):
            e[part] = [row(entry(r, "row", f"exp {e['key']!r} {part} {j + 1}")) for j, r in enumerate(e[part])]
        if e["runs"] not in t["runs"] or set(e["cols"]) - set(t["columns"]):
            raise ValueError(f"002.toml: exp {e['key']!r}: runs or cols not among those the file's header declares")
    declared = {e["key"]: e for e in t["exp"]}
    for k, raw in t["evidence"].items():
        ev = t["evidence"][k] = entry(raw, "evidence", f"evidence {k!r}")
        ev["compare"] = [entry(c, "compare", f"evidence {k!r}") for c in ev["compare"]]
        exps = [declared.get(x.removesuffix(":last")) for x in ev["exps"]]
        bad = [c["a"] for c in ev["compare"] if not c["b"] and "target" not in c]
        bad += [c["a"] for c in ev["compare"] if c.get("target") == "paper" for e in exps if paper(e, c) is None]
        if None in exps or bad:
            raise ValueError(f"002.toml: evidence {k!r}: unknown exps, or no b, target or paper number for {bad}")
    check_claims(t)
    return t


def check_claims(t: dict) -> None:
    """Refuse, before any run, a claim whose rule names an undeclared evidence key or whose test cannot decide one of
    its entries (:func:`replay.reproduce.rules.undecidable`: an interval without a target, a paired test without b)."""
    for c in spec.claims(t, "002.toml"):
        keys = [k for k in (c.rule.decides, c.rule.condition, c.rule.mechanism, c.rule.working) if k]
        if bad := [k for k in keys if k not in t["evidence"]]:
            raise ValueError(f"002.toml: claim {c.id!r}: no [evidence] for {bad}")
        for k, x in ((k, x) for k in keys for x in t["evidence"][k]["compare"]):
            entry = x | ({"target": 0.0} if "target" in x else {})  # the paper's numbers: checked by load
            probe = comparison(dict(key=k, runs="", rows=[], last=[]), blank(x), entry)
            if why := undecidable(probe, probe.test or c.rule.test):
                raise ValueError(f"002.toml: claim {c.id!r}: evidence {k!r}, entry a = {x['a']!r}: {why}")


def blank(c: dict) -> dict:
    """Rows standing in for a compare entry's arms before any run (one run each), to check its test decides it."""
    r = dict(v={c["col"]: [0.0], "pos_rmse": [0.0]}, lost=[False], row={})
    return {c["a"]: r} | ({c["b"]: r} if c["b"] else {})


def row(r: dict) -> dict:
    """A row with its filter (default: the label), parameters ("null": None), table cells ``name`` and ``numbers``."""
    params = {k: None if v == "null" else v for k, v in r["params"].items()}
    name = r["label"] + (f" (q × {params['q_scale']:g})" if "q_scale" in params else "")
    numbers = " / ".join(f"{x:g}" for x in r["paper"]) or "—"
    return r | {"filter": r["filter"] or r["label"], "params": params, "name": name, "numbers": numbers}


def paper(e: dict | None, c: dict, arm: str = "a") -> float | None:
    """The paper's number of the row ``c[arm]`` of experiment ``e`` in the comparison's column (None: not given)."""
    rows = [r for r in (e["rows"] + e["last"] if e else []) if r["label"] == c[arm]]
    return dict(zip(e["cols"], rows[0]["paper"])).get(c["col"]) if rows else None


def experiments(t: dict, seqs: list[str]) -> list[dict]:
    """The experiments, a ``per_sequence`` one as ``<key>-<last 3 characters>`` on each of ``seqs`` (the rows
    ``last`` added on the last); ``group``: the declared key."""
    at = lambda e, s: dict(key=f"{e['key']}-{s[-3:]}", dataset=s, rows=e["rows"] + e["last"] * (s == seqs[-1]))
    on = lambda e: seqs if e["per_sequence"] else [""]  # "": the declared dataset
    return [e | {"group": e["key"]} | (at(e, s) if s else {}) for e in t["exp"] for s in on(e)]


def calls(e: dict, s: dict) -> list[tuple]:
    """Experiment ``e``'s rows as evaluate calls (key, ((label, filter, params), ...), evaluate's arguments): one per
    distinct dataset and task parameters and per repeat of a filter, in row order (evaluate adds the measurements)."""
    kw = dict(dataset=e["dataset"], task=e["task"], runs=s[e["runs"]], first=e.get("first"))
    kw |= dict(seed=s["seed"] + (e["runs"] == "tune"), data_dir=s["data_dir"] if e["runs"] == "bohai" else None)
    out, seen = {}, Counter()  # (parameters, n-th use of a filter with them) -> (evaluate's arguments, rows)
    for a in (a for a in e["rows"] if a["filter"] != "measurements"):
        p = dict(dataset_params=e["dp"] | a["dp"] or None, task_params=a["tp"] or None)
        use = (json.dumps(p, sort_keys=True), a["filter"])
        seen[use] += 1
        out.setdefault((use[0], seen[use]), (kw | p, []))[1].append((a["label"], a["filter"], a["params"]))
    return [(e["key"], tuple(rows), args) for args, rows in out.values()]


def compute(above: float, job: tuple) -> dict:
    """One evaluate call (in a worker): its command; per row the summary, lost flags, per-run ``*_rmse``, ``above2``
    (share of steps with a 3-D error above ``above``) and ``mean3`` (mean over steps of the Euclidean position error),
    ``z_low`` (share of truths under the PSO box's depth bound)."""
    _, rows, kw = job
    fp = {f: p for _, f, p in rows if p} or None
    kw = {k: v for k, v in kw.items() if k != "dataset"}
    ev = evaluate(job[2]["dataset"], EvalOptions(filters=tuple(f for _, f, _ in rows), filter_params=fp, **kw))
    by, out = {r.name: r for r in ev.results}, {"command": command_line(ev.config), "rows": {}}
    z = [pso.below_box(t) for t in ev.truths if t.shape[1] > 2]
    for lab, r in ((lab, by[f]) for lab, f, _ in rows + (("raw measurements", "measurements", 0),) if f in by):
        v = {c: per_run(r, c)[0].tolist() for c in r.runs[0] if c.endswith("_rmse")}
        v["above2"] = [share_above(e["position"], above) for e in r.errors]
        v["mean3"] = [mean_norm(e["position"]) for e in r.errors]
        out["rows"][lab] = dict(row=r.summary, v=v, lost=per_run(r)[1].tolist(), z_low=float(np.mean(z)) if z else None)
    return out


def mean_norm(err: np.ndarray) -> float:
    """The mean over steps of the Euclidean norm of one run's position errors (rows of ``err``; NaN steps left out)."""
    n = np.linalg.norm(err, axis=1)
    n = n[np.isfinite(n)]
    return float(n.mean()) if len(n) else float("nan")


def mean3(r: dict) -> str:
    """A row's mean Euclidean error over runs ± its 95 % t half-width (runs with a finite value)."""
    m, h = t_interval(r["v"]["mean3"])
    return mean_ci({"pos_rmse": m, "pos_rmse_ci95": h})


def run_all(exps, s: dict, ex) -> dict:
    """The calls of ``exps``, costliest first: {key: {label: evidence, ``cmd``: its call's number}, "cmd:<group>": the
    calls' commands, numbered over the experiment's sequences}."""
    todo, E, group = [job for e in exps for job in calls(e, s)], {}, {e["key"]: e["group"] for e in exps}
    heavy = lambda f: 5 if any(x in f for x in ("gwo", "pso", "stcpf")) else 1  # a swarm filter: about 5 PFs
    costs = [kw["runs"] * (kw["first"] or 100) * sum(heavy(f) for _, f, _ in rows) for _, rows, kw in todo]
    done = dict(run_longest_first(partial(compute, s["above"]), todo, costs, [j[0] for j in todo], ex, s["quiet"]))
    for i, (k, _, _) in enumerate(todo):
        (c := E.setdefault(f"cmd:{group[k]}", [])).append(done[i]["command"])
        E.setdefault(k, {}).update({lab: dict(r, cmd=len(c)) for lab, r in done[i]["rows"].items()})
    return E


def variants(e: dict, qs: dict, label: str) -> list[dict]:
    """The first row of each filter of ``qs`` (filter -> q_scale values) with ``q_scale`` set, relabelled."""
    base = {f: next(r for r in e["rows"] if r["filter"] == f) for f in qs}
    new = lambda f, q: dict(label=label.format(f=f, q=q, base=base[f]["label"]), paper=[])
    return [row(base[f] | new(f, q) | {"params": base[f]["params"] | {"q_scale": q}}) for f in qs for q in qs[f]]


def tune(t: dict, exps: list[dict], s: dict, ex) -> dict:
    """{experiment key: {filter: the first ``grid`` q_scale of least mean position RMSE}} for each experiment that
    tunes: a simulation on the seed + 1 (runs "tune"), the Bohai sequence ``tune_seq`` at its rate."""
    grids = [e for e in exps if e["tune"] and (e["runs"] == "mc" or e["dataset"] == t["tune_seq"])]
    grids = [e | dict(key=e["key"] + ":grid", runs="tune" if e["runs"] == "mc" else e["runs"]) for e in grids]
    grids = [g | {"rows": variants(g, dict.fromkeys(g["tune"], t["grid"]), "{f} q×{q:g}")} for g in grids]
    G = run_all(grids, s, ex)
    rmse = lambda g, f, q: np.mean(G[g["key"]][f"{f} q×{q:g}"]["v"]["pos_rmse"])
    return {g["key"][:-5]: {f: min(t["grid"], key=partial(rmse, g, f)) for f in g["tune"]} for g in grids}


def comparison(e: dict, rows: dict, c: dict) -> Comparison:
    """A declared comparison in experiment ``e``: ``target`` in ``a``'s interval, fewer lost (McNemar), or a < b."""
    k, a, b, col = e["key"], rows[c["a"]], rows.get(c["b"]), c["col"]
    if e["runs"] == "bohai" and "raw measurements" in rows:  # every Bohai cell states the raw error it compares with
        k += f" (raw measurements {rows['raw measurements']['row']['pos_rmse']:.3f} m)"
    if "target" in c:
        target = paper(e, c) if c["target"] == "paper" else c["target"]
        name, test = f"{k}: {c['a']} {col}", c["test"] or "interval"
        return Comparison(name, a["v"][col], lost_a=a["lost"], target=target, test=test)
    if c["lost"]:
        m, p = np.mean(a["v"]["pos_rmse"]), paper(e, c, "b")
        gap = f" (residual gap: {c['a']} {m:.3f} vs paper {p}, {m / p:.1f}×)" if p else ""
        return Comparison(f"{k}: lost, {c['a']} vs {c['b']}{gap}", (), (), a["lost"], b["lost"], test="mcnemar")
    return Comparison(f"{k}: {c['a']} < {c['b']}", a["v"][col], b["v"][col], a["lost"], b["lost"], test=c["test"])


def evidence(t: dict, exps, E: dict) -> dict:
    """Rule key -> its comparisons: each of ``compare`` in each experiment of ``exps`` ("<key>:last": the last)."""
    pick = lambda x: [e for e in exps if e["group"] == x.split(":")[0]][-1 if ":" in x else 0 :]
    compare = lambda v: [comparison(e, E[e["key"]], c) for x in v["exps"] for e in pick(x) for c in v["compare"]]
    return {k: compare(v) for k, v in t["evidence"].items()}


def exp_table(ex: list[dict], E: dict, t: dict) -> str:
    """An experiment's table: per row the paper's numbers, ours per column, ours ÷ paper, median, lost, ..."""
    e, out = ex[0], []
    for a, r in ((a, E[e["key"]][a["label"]]) for a in e["rows"] if a["label"] in E[e["key"]]):
        w, p, n = r["row"], a["paper"], len(r["lost"])
        ratio = f"{w['pos_rmse'] / p[0]:.2f}" if p and np.isfinite(w.get("pos_rmse", np.nan)) else "—"
        med, us = w.get("pos_rmse_median", np.nan), w.get("us_per_step", np.nan)
        cols = [mean_ci(w, c) for c in e["cols"]]
        out.append([a["name"], a["numbers"], cols[0], mean3(r), *cols[1:], ratio, f"{med:.3f}"])
        out[-1] += [f"{sum(r['lost'])}/{n}", f"{w.get('diverged', 0)}/{n}", f"{us:.0f}", r["cmd"]]
    heads = [t["columns"][c] for c in e["cols"]]
    head = ["row", "paper", heads[0], MEAN3, *heads[1:], "ours ÷ paper", "median", "lost", "diverged"]
    tab = table(head + ["µs/step", "command"], out)
    return f"{anchor_tag('#e-' + e['key'])}\n\n{tab}\n\n{command_list(t, E['cmd:' + e['key']])}"


def sequence_table(ex: list[dict], E: dict, t: dict) -> str:
    """Rows x sequences: mean position RMSE ± 95 % (mean Euclidean error ± 95 %; lost runs; the raw measurements'
    RMSE on that sequence) [the command that gives it]."""
    rows, group = {a["name"]: a for e in ex for a in e["rows"]}, ex[0]["group"]
    at = lambda e, a: E[e["key"]].get(a["label"]) if a in e["rows"] else None
    raw = lambda e: f"{E[e['key']].get('raw measurements', {}).get('row', {}).get('pos_rmse', np.nan):.3f}"
    cell = lambda r, e: f"{mean_ci(r['row'])} (mean {mean3(r)}; {sum(r['lost'])} lost; raw {raw(e)}) [{r['cmd']}]"
    body = [[k, a["numbers"], *(cell(at(e, a), e) if at(e, a) else "—" for e in ex)] for k, a in rows.items()]
    tab = table(["row", "paper", *(e["dataset"] for e in ex)], body)
    return f"{anchor_tag('#e-' + group)}\n\n{tab}\n\n{command_list(t, E['cmd:' + group], '[n]')}"


def command_list(t: dict, cs: list[str], what: str = "column 'command'") -> str:
    """The numbered commands of a table's evaluate calls, under the heading naming where the table cites them."""
    return t["commands"].format(what) + "\n\n" + "\n".join(f"{i}. `{c}`" for i, c in enumerate(cs, 1))


def document(t: dict, exps, E: dict, chosen: dict, seqs, seed: int) -> str:
    """The verdicts (a claim whose comparisons draw on no experiment is not run) and the template's fields."""
    ev, groups = evidence(t, exps, E), {d["key"]: [e for e in exps if e["group"] == d["key"]] for d in t["exp"]}
    tab = lambda d, ex: (sequence_table if d["per_sequence"] else exp_table)(ex, E, t) if ex else t["no_sequences"]
    fields = {d["key"]: tab(d, groups[d["key"]]) for d in t["exp"]}
    fields |= {"tune_seq": t["tune_seq"], "grid": ", ".join(f"{q:g}" for q in t["grid"])}
    fields |= {"seqs": ", ".join(seqs) or "none found", "z_low": f"{100 * E['t5']['stckf']['z_low']:.1f} %"}
    fields["load"] = ", ".join(f"{x:.1f}" for x in os.getloadavg())  # the machine's load, printed beside the times
    swarm_kernels.entropy_weights(np.array([1.0, 1.5, 10.0]), 1e-12, 1e-4, w := np.empty(3))  # 002 §3.2.2
    fields["entropy"] = "(" + ", ".join(f"{x:.3f}" for x in w) + ")"
    fields["tuned"] = "; ".join(f"{k}: " + ", ".join(f"{f} × {q:g}" for f, q in v.items()) for k, v in chosen.items())
    fields["b_raw"] = raw_text([e for e in exps if e["group"] == "b1hz"], E)
    claims = [c for c in spec.claims(t, "002.toml") if ev[c.rule.decides]]
    return render("002", fields, decide(claims, ev, seed=seed))


def raw_text(ex: list[dict], E: dict) -> str:
    """IGWO-STCPF's position RMSE over the sequences of ``ex`` beside the raw measurements' (the error it compares
    with), as ranges over the sequences."""
    span = lambda lab: [E[e["key"]][lab]["row"]["pos_rmse"] for e in ex if lab in E[e["key"]]]
    ig, raw = span("igwo-stcpf"), span("raw measurements")
    if not ig or not raw:
        return "(no Bohai sequence found)"
    return f"IGWO-STCPF {min(ig):.3f}–{max(ig):.3f} m, the raw measurements {min(raw):.3f}–{max(raw):.3f} m"


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Tune the baselines, compute every experiment with their tuned rows, decide the claims, write the document."""
    watch, t = Stopwatch(), load()
    seqs, n = registry.local_ids(t["sequences"], data_dir), t["quick"] if quick else t["runs"]
    mc, bohai = runs or n["mc"], n["bohai"] if quick else max(n["bohai"], runs or n["bohai"])
    s = dict(seed=seed, data_dir=data_dir, quiet=quiet, mc=mc, tune=max(2, mc // 5), bohai=bohai, above=t["above"])
    exps = experiments(t, seqs[-n["sequences"] :] if quick else seqs)
    with pool(workers()) as ex:
        chosen = tune(t, exps, s, ex)
        for e in (e for e in exps if e["dataset"] != t["tune_seq"]):
            tuned = chosen.get(e["key"] if e["runs"] == "mc" else f"{e['group']}-{t['tune_seq'][-3:]}", {})
            e["rows"] = e["rows"] + variants(e, {f: (q,) for f, q in tuned.items()}, "{base}, q tuned")
        E = run_all(exps, s, ex)
    cmd = f"replay reproduce 002{f' --runs {runs}' if runs else ''}{' --quick' if quick else ''} --seed {seed}"
    cmd += " --data-dir ../shared/datasets/bohai" if data_dir else ""
    text = document(t, exps, E, chosen, seqs, seed) + footer(cmd, watch.seconds)
    path = write_document(doc or "docs/reproduction/002.md", text)
    if not quiet:
        print(f"wrote {path} ({watch.seconds:.0f} s)")
    return path
