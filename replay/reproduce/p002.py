"""``replay reproduce 002``: the IGWO-STCPF paper (UNGM, sonar Tables 5/6, Figs. 17/18, Bohai) as data.

``replay/papers/002.toml`` declares everything (:func:`load` checks every key): the experiments ``[[exp]]``
(dataset, task, parameters, the tuned baselines, ``rows``: label, filter, parameters, the paper's numbers),
the comparisons ``[evidence]`` each rule key draws on and the claims ``[[claim]]`` with their rules
(:mod:`.spec`); ``replay/papers/002.md`` is the prose. A row, an ablation, a comparison or a claim is a TOML
edit; a new experiment also needs its ``${key}`` in the template. A ``per_sequence`` experiment becomes one
experiment ``<key>-<seq[-3:]>`` per Bohai sequence found, its ``last`` rows on the last sequence only.
Each row is a filter of one :func:`replay.run.evaluation.evaluate` call (``replay eval``; the tables print
the commands); the rows of one experiment share the seed, so they are paired run by run. Baselines at their
best: each ``tune`` filter's ``q_scale`` over ``grid``, chosen by the least mean position RMSE on seed + 1
(simulations, a fifth of the runs) or on ``tune_seq`` (Bohai, same rate), is the row "<row>, q tuned".
"""

from __future__ import annotations

import json
import os
from functools import partial

import numpy as np

from replay.data import registry
from replay.filters.p002 import swarm_kernels
from replay.run.evaluation import evaluate
from replay.run.manifest import command_line

from . import spec
from .pool import pool, run_longest_first, workers
from .render import anchor_tag, render, table
from .rules import Comparison, decide, per_run
from .verdict import Stopwatch, footer, write_document

TOP = dict.fromkeys("grid columns runs quick bounds sequences tune_seq no_sequences exp evidence claim".split(), ...)
EXP = dict(key=..., task=..., rows=..., dataset="", dp={}, cols=["pos_rmse"], tune=[], runs="mc", first=None)
EXP |= dict(per_sequence=False, last=[])  # ...: required
ROW, EVIDENCE = dict(label=..., filter="", params={}, paper=[], dp={}, tp={}), dict(exps=..., compare=...)
CMP = dict(a=..., b="", target=None, col="pos_rmse", lost=False, gap=None)
HEAD = ["ours ÷ paper", "median", "lost", "diverged", "µs/step", "command"]
pm = lambda r, c: "n/a" if r.get(c) is None or not np.isfinite(r[c]) else f"{r[c]:.3f} ± {r[f'{c}_ci95']:.3f}"
name = lambda a: a["label"] + (f" (q × {a['params']['q_scale']:g})" if "q_scale" in a["params"] else "")
paper = lambda a: " / ".join(f"{x:g}" for x in a["paper"]) or "—"
cmds = lambda cs, what="column 'command'": (
    f"Commands ({what}: the one that gives the row exactly):\n\n"
    + "\n".join(f"{i}. `{c}`" for i, c in enumerate(cs, 1))
)


def checked(entry, keys: dict, where: str) -> dict:
    """``entry`` with the defaults of ``keys`` (``...``: required); an unknown or a missing key is refused in
    one line naming the file and the entry (generic: any paper's table could use it)."""
    bad = sorted(set(entry) - set(keys)) if isinstance(entry, dict) else ["(not a table)"]
    if bad or (bad := [f"missing {k}" for k, v in keys.items() if v is ... and k not in entry]):
        raise ValueError(f"002.toml: {where}: unknown key(s) or missing: {', '.join(map(str, bad))}")
    return {**keys, **entry}


def row(entry, where: str) -> dict:
    """A row; its filter defaults to its label, "null" in ``params`` stands for None (TOML has no null)."""
    r = checked(entry, ROW, where)
    return r | dict(
        filter=r["filter"] or r["label"], params={k: None if v == "null" else v for k, v in r["params"].items()}
    )


def load() -> dict:
    """``replay/papers/002.toml``, every experiment, row, comparison and claim checked (:func:`checked`)."""
    t = checked(spec.load("002"), TOP, "top level")
    for i, raw in enumerate(t["exp"]):
        e = t["exp"][i] = checked(raw, EXP, f"exp {raw.get('key', i + 1)!r}")
        e.update({p: [row(r, f"exp {e['key']!r} {p} {j + 1}") for j, r in enumerate(e[p])] for p in ("rows", "last")})
        ok = e["runs"] in t["runs"], set(e["cols"]) <= set(t["columns"]), bool(e["dataset"] or e["per_sequence"])
        if bad := [k for k, good in zip(("runs", "cols", "dataset"), ok) if not good]:
            raise ValueError(f"002.toml: exp {e['key']!r}: {', '.join(bad)} not as the file's header declares")
    for k, raw in t["evidence"].items():
        ev = t["evidence"][k] = checked(raw, EVIDENCE, f"evidence {k!r}")
        ev["compare"] = [checked(c, CMP, f"evidence {k!r}") for c in ev["compare"]]
        if bad := [x for x in ev["exps"] if x.removesuffix(":last") not in {e["key"] for e in t["exp"]}]:
            raise ValueError(f"002.toml: evidence {k!r}: unknown experiment(s) {bad}")
    spec.claims(t, "002.toml")
    return t


def experiments(t: dict, seqs: list[str]) -> list[dict]:
    """The declared experiments, each ``per_sequence`` one expanded over ``seqs``; ``group``: the declared key."""
    out = []
    for e in t["exp"]:
        one = lambda s: dict(
            key=f"{e['key']}-{s[-3:]}", dataset=s, rows=e["rows"] + (e["last"] if s == seqs[-1] else [])
        )
        out += [e | {"group": e["key"]} | one(s) for s in seqs] if e["per_sequence"] else [e | {"group": e["key"]}]
    return out


def variants(e: dict, qs: dict, label: str) -> list[dict]:
    """The first row of each filter of ``qs`` (filter -> q_scale values) with ``q_scale`` set, relabelled."""
    base = {f: next(r for r in e["rows"] if r["filter"] == f) for f in qs}
    return [
        b | dict(label=label.format(f=f, q=q, base=b["label"]), paper=[], params=b["params"] | {"q_scale": q})
        for f, b in base.items()
        for q in qs[f]
    ]


def jobs(exps, s: dict) -> list[tuple]:
    """One evaluate call per distinct dataset and task parameters of an experiment's rows, each filter once per
    call (rows in order). A job: (experiment key, ((label, filter, params), ...), evaluate's keyword arguments)."""
    out = []
    for e in exps:
        calls = []  # (dataset and task parameters as JSON, rows)
        for a in (a for a in e["rows"] if a["filter"] != "measurements"):  # evaluate adds the measurements
            key = json.dumps([e["dp"] | a["dp"], a["tp"]], sort_keys=True)
            c = next((c for c in calls if c[0] == key and a["filter"] not in {x[1] for x in c[1]}), None)
            if c is None:
                calls.append(c := (key, []))
            c[1].append((a["label"], a["filter"], a["params"]))
        kw = dict(
            dataset=e["dataset"],
            task=e["task"],
            runs=s[e["runs"]],
            first=e["first"],
            seed=s["seed"] + (e["runs"] == "tune"),
        )
        for (dp, tp), rows in ((json.loads(key), rows) for key, rows in calls):
            out.append(
                (
                    e["key"],
                    tuple(rows),
                    kw
                    | dict(
                        dataset_params=dp or None,
                        task_params=tp or None,
                        data_dir=s["data_dir"] if e["runs"] == "bohai" else None,
                    ),
                )
            )
    return out


def compute(bounds: dict, job) -> dict:
    """One evaluate call (a worker process), reduced to its command and per row: the summary, the per-run values
    of each RMSE column and of "above2" (share of steps above ``bounds["error"]``), lost flags, z_low (§4.1)."""
    _, rows, kw = job
    ev = evaluate(filters=tuple(f for _, f, _ in rows), filter_params={f: p for _, f, p in rows if p} or None, **kw)
    by, out = {r.name: r for r in ev.results}, {"command": command_line(ev.config), "rows": {}}
    z = [float(np.mean(t[:, 2] < bounds["depth"])) for t in ev.truths if t.shape[1] > 2]
    for lab, r in (
        (lab, by[f]) for lab, f in [x[:2] for x in rows] + [("raw measurements", "measurements")] if f in by
    ):
        v = {c: per_run(r, c)[0].tolist() for c in r.runs[0] if c.endswith("_rmse")}
        v["above2"] = [float(np.mean(np.linalg.norm(e["position"], axis=1) > bounds["error"])) for e in r.errors]
        keep = [
            k
            for k in r.summary
            if k.endswith(("rmse", "ci95", "median")) or k in ("lost", "diverged", "runs", "us_per_step")
        ]
        out["rows"][lab] = dict(
            row={k: r.summary[k] for k in keep},
            v=v,
            lost=per_run(r)[1].tolist(),
            z_low=float(np.mean(z)) if z else None,
        )
    return out


def run_all(exps, s: dict, ex) -> dict:
    """{exp key: {label: row evidence}, "cmd:<key>": [commands]}, the commands numbered in job order."""
    todo = jobs(exps, s)
    heavy = lambda f: 5 if "gwo" in f or "pso" in f or "stcpf" in f else 1  # cost: a swarm filter ~5 PFs
    cost = [kw["runs"] * (kw["first"] or 100) * sum(heavy(f) for _, f, _ in rows) for _, rows, kw in todo]
    names = [f"{k}: {', '.join(r[0] for r in rows)}" for k, rows, _ in todo]
    done, E = dict(run_longest_first(partial(compute, s["bounds"]), todo, cost, names, ex, s["quiet"], "002 ")), {}
    for i, (k, _, _) in enumerate(todo):
        (c := E.setdefault(f"cmd:{k}", [])).append(done[i]["command"])
        E.setdefault(k, {}).update({lab: dict(r, cmd=len(c)) for lab, r in done[i]["rows"].items()})
    return E


def compute_all(t: dict, runs, seed, data_dir, quick, quiet) -> tuple:
    """(experiments with their tuned rows, evidence, chosen q_scale, Bohai sequences found): the grids first."""
    seqs = [i for i in sorted(registry.all_datasets()) if i.startswith(t["sequences"]) and registry.locate(i, data_dir)]
    n = t["quick"] if quick else t["runs"]
    mc, bohai = runs or n["mc"], n["bohai"] if quick else max(n["bohai"], runs or n["bohai"])
    s = dict(seed=seed, data_dir=data_dir, quiet=quiet, mc=mc, tune=max(2, mc // 5), bohai=bohai, bounds=t["bounds"])
    exps = experiments(t, seqs[-n["sequences"] :] if quick else seqs)
    grids = [e for e in exps if e["tune"] and (e["runs"] == "mc" or e["dataset"] == t["tune_seq"])]
    grids = [e | dict(key=e["key"] + ":grid", runs="tune" if e["runs"] == "mc" else e["runs"]) for e in grids]
    with pool(workers()) as ex:
        G = run_all(
            [g | dict(rows=variants(g, {f: t["grid"] for f in g["tune"]}, "{f} q×{q:g}")) for g in grids], s, ex
        )
        chosen = {
            g["key"][:-5]: {
                f: min(t["grid"], key=lambda q: np.mean(G[g["key"]][f"{f} q×{q:g}"]["v"]["pos_rmse"]))
                for f in g["tune"]
            }
            for g in grids
        }
        for e in exps:
            q = (
                chosen.get(e["key"] if e["runs"] == "mc" else f"{e['group']}-{t['tune_seq'][-3:]}", {})
                if e["dataset"] != t["tune_seq"]
                else {}
            )
            e["rows"] = e["rows"] + variants(e, {f: (v,) for f, v in q.items()}, "{base}, q tuned")
        return exps, run_all(exps, s, ex), chosen, seqs


def comparison(rows: dict, k: str, c: dict) -> Comparison:
    """One declared comparison in experiment ``k``: the paper's ``target`` inside ``a``'s 95 % interval; or ``a``
    loses fewer runs than ``b`` (``lost``: exact McNemar, ``gap`` beside ``a``'s mean); or ``a`` < ``b`` by run."""
    a, b = rows[c["a"]], rows.get(c["b"])
    if c["target"] is not None:
        return Comparison(
            f"{k}: {c['a']} {c['col']}", a["v"][c["col"]], lost_a=a["lost"], target=c["target"], test="interval"
        )
    if c["lost"]:
        m = np.mean(a["v"]["pos_rmse"])
        gap = f" (residual gap: {c['a']} {m:.3f} vs paper {c['gap']}, {m / c['gap']:.1f}×)" if c["gap"] else ""
        return Comparison(f"{k}: lost, {c['a']} vs {c['b']}{gap}", lost_a=a["lost"], lost_b=b["lost"], test="mcnemar")
    return Comparison(f"{k}: {c['a']} < {c['b']}", a["v"][c["col"]], b["v"][c["col"]], a["lost"], b["lost"])


def exp_table(ex: list[dict], E: dict, t: dict) -> str:
    """An experiment's table: per row the paper's numbers, ours per column, ours ÷ paper, median, lost, ..."""
    e, out = ex[0], []
    for a, r in ((a, E[e["key"]][a["label"]]) for a in e["rows"] if a["label"] in E[e["key"]]):
        row, p, n = r["row"], a["paper"], len(r["lost"])
        ratio = f"{row['pos_rmse'] / p[0]:.2f}" if p and np.isfinite(row.get("pos_rmse", np.nan)) else "—"
        tail = [f"{row.get('pos_rmse_median', np.nan):.3f}", f"{sum(r['lost'])}/{n}", f"{row.get('diverged', 0)}/{n}"]
        out.append(
            [
                name(a),
                paper(a),
                *(pm(row, c) for c in e["cols"]),
                ratio,
                *tail,
                f"{row.get('us_per_step', np.nan):.0f}",
                r["cmd"],
            ]
        )
    head = ["row", "paper", *(t["columns"][c] for c in e["cols"]), *HEAD]
    return f"{anchor_tag('#e-' + e['key'])}\n\n{table(head, out)}\n\n{cmds(E['cmd:' + e['key']])}"


def sequence_table(ex: list[dict], E: dict, t: dict) -> str:
    """Rows x sequences: mean position RMSE ± 95 % (lost runs) [the command that gives it]."""
    off = np.cumsum([0] + [len(E[f"cmd:{e['key']}"]) for e in ex])
    cell = lambda i, r: (
        "—" if r is None else f"{pm(r['row'], 'pos_rmse')} ({sum(r['lost'])} lost) [{off[i] + r['cmd']}]"
    )
    at = lambda e, a: E[e["key"]].get(a["label"]) if a in e["rows"] else None
    body = [
        [k, paper(a)] + [cell(i, at(e, a)) for i, e in enumerate(ex)]
        for k, a in {name(a): a for e in ex for a in e["rows"]}.items()
    ]
    head, cs = ["row", "paper"] + [e["dataset"] for e in ex], [c for e in ex for c in E[f"cmd:{e['key']}"]]
    return f"{anchor_tag('#e-' + ex[0]['group'])}\n\n{table(head, body)}\n\n{cmds(cs, '[n]')}"


def document(t: dict, exps, E: dict, chosen: dict, seqs, seed: int) -> str:
    """The verdicts (a claim whose comparisons draw on no experiment is not run) and the template's fields."""
    groups = {d["key"]: [e for e in exps if e["group"] == d["key"]] for d in t["exp"]}
    pick = lambda x: groups[x[:-5]][-1:] if x.endswith(":last") else groups[x]
    ev = {
        k: [comparison(E[e["key"]], e["key"], c) for x in v["exps"] for e in pick(x) for c in v["compare"]]
        for k, v in t["evidence"].items()
    }
    keys = lambda c: [k for k in (c.rule.decides, c.rule.condition, c.rule.mechanism) if k]
    claims = [c for c in spec.claims(t, "002.toml") if all(ev.get(k, 1) for k in keys(c))]
    fields = {
        d["key"]: (sequence_table if d["per_sequence"] else exp_table)(groups[d["key"]], E, t)
        if groups[d["key"]]
        else t["no_sequences"]
        for d in t["exp"]
    }
    swarm_kernels.entropy_weights(np.array([1.0, 1.5, 10.0]), 1e-12, 1e-4, w := np.empty(3))  # 002 §3.2.2
    fields |= dict(z_low=f"{100 * E['t5']['stckf']['z_low']:.1f} %", seqs=", ".join(seqs) or "none found")
    fields |= dict(
        tune_seq=t["tune_seq"],
        grid=", ".join(f"{q:g}" for q in t["grid"]),
        load=", ".join(f"{x:.1f}" for x in os.getloadavg()),
    )
    fields["entropy"] = "(" + ", ".join(f"{x:.3f}" for x in w) + ")"
    fields["tuned"] = "; ".join(f"{k}: " + ", ".join(f"{f} × {q:g}" for f, q in v.items()) for k, v in chosen.items())
    return render("002", fields, decide(claims, ev, seed=seed))


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Compute every experiment, decide the claims, write the document."""
    watch, t = Stopwatch(), load()
    exps, E, chosen, seqs = compute_all(t, runs, seed, data_dir, quick, quiet)
    cmd = f"replay reproduce 002{f' --runs {runs}' if runs else ''}{' --quick' if quick else ''} --seed {seed}"
    text = document(t, exps, E, chosen, seqs, seed) + footer(
        cmd + (" --data-dir ../shared/datasets/bohai" if data_dir else ""), watch.seconds
    )
    path = write_document(doc or "docs/reproduction/002.md", text)
    if not quiet:
        print(f"wrote {path} ({watch.seconds:.0f} s)")
    return path
