"""``replay reproduce 002``: the IGWO-STCPF paper (UNGM, sonar Tables 5/6, Figs. 17/18, Bohai) as data.

``replay/papers/002.toml`` declares the experiments, the comparisons and the claims (its comments define every
key, :func:`load` checks them): a row, an ablation, a comparison or a claim is a TOML edit (a new experiment
also needs its ``${key}`` in ``replay/papers/002.md``). Each row is a filter of one ``replay eval`` call
(:func:`replay.run.evaluation.evaluate`); one experiment's rows share the seed, so they are paired by run.
"""

import json
import os
from functools import partial

import numpy as np

from replay.campaign.longest import pool, run_longest_first, workers
from replay.data import registry
from replay.filters.p002 import swarm_kernels
from replay.run.evaluation import evaluate
from replay.run.manifest import command_line
from replay.util.portable import write_document

from . import spec
from .render import anchor_tag, render, table
from .rules import Comparison, decide, per_run
from .tables import Stopwatch, footer

TOP = dict.fromkeys("grid columns runs quick bounds sequences tune_seq no_sequences exp evidence claim".split(), ...)
EXP = dict(key=..., task=..., rows=..., dataset="", dp={}, cols=["pos_rmse"], tune=[], runs="mc", first=None)
EXP |= dict(per_sequence=False, last=[])  # the keys of 002.toml's tables and their defaults (...: required)
ROW, EVIDENCE = dict(label=..., filter="", params={}, paper=[], dp={}, tp={}), dict(exps=..., compare=...)
CMP = dict(a=..., b="", target=None, col="pos_rmse", lost=False, gap=None)
pm = lambda r, c: "n/a" if r.get(c) is None or not np.isfinite(r[c]) else f"{r[c]:.3f} ± {r[f'{c}_ci95']:.3f}"
name = lambda a: a["label"] + (f" (q × {a['params']['q_scale']:g})" if "q_scale" in a["params"] else "")
paper = lambda a: " / ".join(f"{x:g}" for x in a["paper"]) or "—"
WHICH = "Commands ({}: the one that gives the row exactly):\n\n"
cmds = lambda cs, what="column 'command'": WHICH.format(what) + "\n".join(f"{i}. `{c}`" for i, c in enumerate(cs, 1))


def checked(entry, keys: dict, where: str) -> dict:
    """``entry`` with the defaults of ``keys``; an unknown or a missing key is refused naming the entry (generic)."""
    bad = [f"unknown {k!r}" for k in entry if k not in keys] if isinstance(entry, dict) else ["not a table"]
    if bad := bad or [f"missing {k!r}" for k, v in keys.items() if v is ... and k not in entry]:
        raise ValueError(f"002.toml: {where}: {', '.join(bad)}")
    return {**keys, **entry}


def load() -> dict:
    """``replay/papers/002.toml``, every key checked; a row's filter defaults to its label, "null" is None."""
    t, null = checked(spec.load("002"), TOP, "top level"), lambda v: None if v == "null" else v
    row = lambda r: r | {"filter": r["filter"] or r["label"], "params": {k: null(v) for k, v in r["params"].items()}}
    rows = lambda e, p: [row(checked(r, ROW, f"exp {e['key']!r} {p} {j + 1}")) for j, r in enumerate(e[p])]
    for i, raw in enumerate(t["exp"]):
        e = t["exp"][i] = checked(raw, EXP, f"exp {i + 1}")
        e |= {"rows": rows(e, "rows"), "last": rows(e, "last")}
        if e["runs"] not in t["runs"] or set(e["cols"]) - set(t["columns"]):
            raise ValueError(f"002.toml: exp {e['key']!r}: runs or cols not among those the file's header declares")
    for k, raw in t["evidence"].items():
        ev = t["evidence"][k] = checked(raw, EVIDENCE, f"evidence {k!r}")
        ev["compare"] = [checked(c, CMP, f"evidence {k!r}") for c in ev["compare"]]
        bad = [x for x in ev["exps"] if x.removesuffix(":last") not in {e["key"] for e in t["exp"]}]
        if bad := bad + [c["a"] for c in ev["compare"] if not c["b"] and c["target"] is None]:
            raise ValueError(f"002.toml: evidence {k!r}: unknown exps or a comparison without b or target {bad}")
    for c in spec.claims(t, "002.toml"):
        if bad := [k for k in (c.rule.decides, c.rule.condition, c.rule.mechanism) if k and k not in t["evidence"]]:
            raise ValueError(f"002.toml: claim {c.id!r}: no [evidence] for {bad}")
    return t


def experiments(t: dict, seqs: list[str]) -> list[dict]:
    """The declared experiments, each ``per_sequence`` one expanded over ``seqs``; ``group``: the declared key."""
    at = lambda e, s: s and dict(key=f"{e['key']}-{s[-3:]}", dataset=s, rows=e["rows"] + e["last"] * (s == seqs[-1]))
    return [e | {"group": e["key"]} | (at(e, s) or {}) for e in t["exp"] for s in (seqs if e["per_sequence"] else [""])]


def compute(bounds: dict, job) -> dict:
    """One evaluate call (in a worker): its command; per row the summary, lost flags, z_low (§4.1), per-run values."""
    _, rows, kw = job
    ev = evaluate(filters=tuple(f for _, f, _ in rows), filter_params={f: p for _, f, p in rows if p} or None, **kw)
    by, out = {r.name: r for r in ev.results}, {"command": command_line(ev.config), "rows": {}}
    z = [float(np.mean(t[:, 2] < bounds["depth"])) for t in ev.truths if t.shape[1] > 2]
    for lab, r in ((lab, by[f]) for lab, f, _ in rows + (("raw measurements", "measurements", 0),) if f in by):
        v = {c: per_run(r, c)[0].tolist() for c in r.runs[0] if c.endswith("_rmse")}
        v["above2"] = [float(np.mean(np.linalg.norm(e["position"], axis=1) > bounds["error"])) for e in r.errors]
        out["rows"][lab] = dict(row=r.summary, v=v, lost=per_run(r)[1].tolist(), z_low=float(np.mean(z)) if z else None)
    return out


def run_all(exps, s: dict, ex) -> dict:
    """Each experiment's rows in evaluate calls, one per distinct dataset and task parameters and per repeat of a
    filter, in row order, in worker processes: {exp key: {label: row evidence}, "cmd:<key>": [their commands]}."""
    todo, E = [], {}  # todo: (experiment key, ((label, filter, params), ...), evaluate's arguments)
    for e in exps:
        calls, seen = {}, []  # (parameters as JSON, n-th call with them) -> rows; evaluate adds the measurements
        for a in (a for a in e["rows"] if a["filter"] != "measurements"):
            seen.append((json.dumps([e["dp"] | a["dp"], a["tp"]], sort_keys=True), a["filter"]))
            calls.setdefault((seen[-1][0], seen.count(seen[-1]) - 1), []).append((a["label"], a["filter"], a["params"]))
        kw = dict(dataset=e["dataset"], task=e["task"], runs=s[e["runs"]], first=e["first"])
        kw |= dict(seed=s["seed"] + (e["runs"] == "tune"), data_dir=s["data_dir"] if e["runs"] == "bohai" else None)
        for (dp, tp), rows in ((json.loads(key), rows) for (key, _), rows in calls.items()):
            todo.append((e["key"], tuple(rows), kw | dict(dataset_params=dp or None, task_params=tp or None)))
    heavy = lambda f: 5 if "gwo" in f or "pso" in f or "stcpf" in f else 1  # cost: a swarm filter ~5 PFs
    cost = [kw["runs"] * (kw["first"] or 100) * sum(heavy(f) for _, f, _ in rows) for _, rows, kw in todo]
    done = dict(run_longest_first(partial(compute, s["bounds"]), todo, cost, [j[0] for j in todo], ex, s["quiet"]))
    for i, (k, _, _) in enumerate(todo):
        (c := E.setdefault(f"cmd:{k}", [])).append(done[i]["command"])
        E.setdefault(k, {}).update({lab: dict(r, cmd=len(c)) for lab, r in done[i]["rows"].items()})
    return E


def variants(e: dict, qs: dict, label: str) -> list[dict]:
    """The first row of each filter of ``qs`` (filter -> q_scale values) with ``q_scale`` set, relabelled."""
    base = {f: next(r for r in e["rows"] if r["filter"] == f) for f in qs}
    new = lambda f, q: dict(label=label.format(f=f, q=q, base=base[f]["label"]), paper=[])
    return [base[f] | new(f, q) | {"params": base[f]["params"] | {"q_scale": q}} for f in qs for q in qs[f]]


def comparison(rows: dict, k: str, c: dict) -> Comparison:
    """A declared comparison in experiment ``k``: ``target`` in ``a``'s interval, fewer lost (McNemar), or a < b."""
    a, b, col, who = rows[c["a"]], rows.get(c["b"]), c["col"], f"{k}: {c['a']}"
    if c["target"] is not None:
        return Comparison(f"{who} {col}", a["v"][col], lost_a=a["lost"], target=c["target"], test="interval")
    if c["lost"]:
        m = np.mean(a["v"]["pos_rmse"])
        gap = f" (residual gap: {c['a']} {m:.3f} vs paper {c['gap']}, {m / c['gap']:.1f}×)" if c["gap"] else ""
        return Comparison(f"{k}: lost, {c['a']} vs {c['b']}{gap}", (), (), a["lost"], b["lost"], test="mcnemar")
    return Comparison(f"{who} < {c['b']}", a["v"][col], b["v"][col], a["lost"], b["lost"])


def evidence(t: dict, exps, E: dict) -> dict:
    """Rule key -> its comparisons: each of ``compare`` in each experiment of ``exps`` (the TOML's comments)."""
    pick = lambda x: [e["key"] for e in exps if e["group"] == x.split(":")[0]][-1 if ":" in x else 0 :]
    compare = lambda v: [comparison(E[e], e, c) for x in v["exps"] for e in pick(x) for c in v["compare"]]
    return {k: compare(v) for k, v in t["evidence"].items()}


def exp_table(ex: list[dict], E: dict, t: dict) -> str:
    """An experiment's table: per row the paper's numbers, ours per column, ours ÷ paper, median, lost, ..."""
    e, out = ex[0], []
    for a, r in ((a, E[e["key"]][a["label"]]) for a in e["rows"] if a["label"] in E[e["key"]]):
        w, p, n = r["row"], a["paper"], len(r["lost"])
        ratio = f"{w['pos_rmse'] / p[0]:.2f}" if p and np.isfinite(w.get("pos_rmse", np.nan)) else "—"
        med, us = w.get("pos_rmse_median", np.nan), w.get("us_per_step", np.nan)
        out.append([name(a), paper(a), *(pm(w, c) for c in e["cols"]), ratio, f"{med:.3f}", f"{sum(r['lost'])}/{n}"])
        out[-1] += [f"{w.get('diverged', 0)}/{n}", f"{us:.0f}", r["cmd"]]
    head = ["row", "paper", *(t["columns"][c] for c in e["cols"]), "ours ÷ paper", "median", "lost", "diverged"]
    tab = table(head + ["µs/step", "command"], out)
    return f"{anchor_tag('#e-' + e['key'])}\n\n{tab}\n\n{cmds(E['cmd:' + e['key']])}"


def sequence_table(ex: list[dict], E: dict, t: dict) -> str:
    """Rows x sequences: mean position RMSE ± 95 % (lost runs) [the command that gives it]."""
    rows, off = {name(a): a for e in ex for a in e["rows"]}, np.cumsum([0] + [len(E[f"cmd:{e['key']}"]) for e in ex])
    at = lambda e, a: E[e["key"]].get(a["label"]) if a in e["rows"] else None
    cell = lambda i, r: f"{pm(r['row'], 'pos_rmse')} ({sum(r['lost'])} lost) [{off[i] + r['cmd']}]" if r else "—"
    body = [[k, paper(a), *(cell(i, at(e, a)) for i, e in enumerate(ex))] for k, a in rows.items()]
    head, cs = ["row", "paper", *(e["dataset"] for e in ex)], [c for e in ex for c in E[f"cmd:{e['key']}"]]
    return f"{anchor_tag('#e-' + ex[0]['group'])}\n\n{table(head, body)}\n\n{cmds(cs, '[n]')}"


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
    claims = [c for c in spec.claims(t, "002.toml") if ev[c.rule.decides]]
    return render("002", fields, decide(claims, ev, seed=seed))


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Tune the baselines (each ``tune`` filter's first ``grid`` value of least mean position RMSE on the data the
    TOML's header names), compute every experiment with the tuned rows, decide the claims, write the document."""
    watch, t = Stopwatch(), load()
    seqs = [i for i in sorted(registry.all_datasets()) if i.startswith(t["sequences"]) and registry.locate(i, data_dir)]
    n = t["quick"] if quick else t["runs"]
    mc, bohai = runs or n["mc"], n["bohai"] if quick else max(n["bohai"], runs or n["bohai"])
    s = dict(seed=seed, data_dir=data_dir, quiet=quiet, mc=mc, tune=max(2, mc // 5), bohai=bohai, bounds=t["bounds"])
    exps = experiments(t, seqs[-n["sequences"] :] if quick else seqs)
    grids = [e for e in exps if e["tune"] and (e["runs"] == "mc" or e["dataset"] == t["tune_seq"])]
    grids = [e | dict(key=e["key"] + ":grid", runs="tune" if e["runs"] == "mc" else e["runs"]) for e in grids]
    grids = [g | {"rows": variants(g, dict.fromkeys(g["tune"], t["grid"]), "{f} q×{q:g}")} for g in grids]
    on = lambda e: e["key"] if e["runs"] == "mc" else f"{e['group']}-{t['tune_seq'][-3:]}"  # where e's q is tuned
    with pool(workers()) as ex:
        G = run_all(grids, s, ex)
        rmse = lambda g, f, q: np.mean(G[g["key"]][f"{f} q×{q:g}"]["v"]["pos_rmse"])
        chosen = {g["key"][:-5]: {f: min(t["grid"], key=partial(rmse, g, f)) for f in g["tune"]} for g in grids}
        for e in (e for e in exps if e["dataset"] != t["tune_seq"]):
            e["rows"] = e["rows"] + variants(e, {f: (q,) for f, q in chosen.get(on(e), {}).items()}, "{base}, q tuned")
        E = run_all(exps, s, ex)
    cmd = f"replay reproduce 002{f' --runs {runs}' if runs else ''}{' --quick' if quick else ''} --seed {seed}"
    cmd += " --data-dir ../shared/datasets/bohai" if data_dir else ""
    text = document(t, exps, E, chosen, seqs, seed) + footer(cmd, watch.seconds)
    path = write_document(doc or "docs/reproduction/002.md", text)
    if not quiet:
        print(f"wrote {path} ({watch.seconds:.0f} s)")
    return path
