"""Reproduction of paper 001 (AUKF vs UKF, small-AUV dead reckoning in currents), §5 Fig. 3–5: the paper prints
figures only (per-time RMSE of north, east, depth, body velocity and acceleration of UKF and AUKF).

Everything declared (experiments, the UKF's tuning grid and rule, tables, the comparisons the claims draw on, the
claims with their rules (:mod:`.spec`), figures) is data in ``replay/papers/001.toml``, whose comments give its
reading rules; :func:`load` refuses an unknown or missing key (:data:`SCHEMA`) and a job or info list named but not
declared. The prose is ``replay/papers/001.md`` (:mod:`.render`). Adding an ablation is a TOML edit: a ``job``, a
row in its ``[[table]]`` (and a comparison in ``[evidence]`` if a claim draws on it); a claim: a ``[[claim]]``.
"""

from pathlib import Path

import numpy as np

from replay.campaign.longest import Job, evaluate_jobs
from replay.filters.p001.aukf import final_estimate, history
from replay.outputs import plots as draw
from replay.outputs.palette import colour
from replay.tune.grid import lowest_then_consistent
from replay.tune.grid import points as grid_points
from replay.util.errors import ReplayError
from replay.util.portable import write_document

from . import spec as papers
from .render import fmt, found, render
from .render import table as md
from .rules import Comparison, decide, per_run
from .tables import Stopwatch, combine, command, commands, footer, row, table

SCHEMA = {  # kind of entry -> its keys ("key?": optional; :func:`.spec.check`)
    "top level": "dataset runs quick_runs sweep_runs primary metrics cell cell_job cell_rows job quantities plot "
    "tuning table info evidence traces nees relabel claim",
    "tuning": "filter data grid runs seed_offset tie anees label columns",
    "cell": "key title data full?",
    "cell_job": "suffix filters params?",
    "job": "key filters dataset? data? params? task? sweep? at_most? full?",
    "table": "name metrics paired rows info?",
    "info": "head key format component? abs?",
    "evidence": "name metric a b fa? fb?",
    "plot": "file track title filters",
    "traces": "job label panels title alt text",
}


def load() -> dict:
    """``replay/papers/001.toml``, every entry checked (module docstring); the claims by :mod:`.spec`."""
    s = papers.check(papers.load("001"), SCHEMA["top level"], "001.toml: top level")
    entries = [("tuning", s["tuning"]), ("traces", s["traces"])]
    entries += [(k, x) for k in ("cell", "cell_job", "job", "table", "plot") for x in s[k]]
    entries += [(k, x) for k in ("info", "evidence") for xs in s[k].values() for x in xs]
    for kind, e in entries:
        name = next((f" {e[k]!r}" for k in ("key", "name", "file", "head", "suffix", "job") if k in e), "")
        papers.check(e, SCHEMA[kind], f"001.toml: {kind}{name}")
    planned = {j.key for j in jobs(s, False, {}, 1, 1)}
    used = [r[1] for t in s["table"] for r in t["rows"]] + [f[1] for x in s["plot"] for f in x["filters"]]
    used += [c[x][0] for cs in s["evidence"].values() for c in cs for x in "ab"] + [s["primary"], s["traces"]["job"]]
    unknown = {k for k in used if k not in planned} | {t["info"] for t in s["table"] if "info" in t} - set(s["info"])
    if unknown:
        raise ValueError(f"001.toml: jobs or info lists named but not declared: {sorted(unknown)}")
    papers.claims(s, "001.toml")  # the claims' schema (:mod:`.spec`)
    return s


def jobs(s: dict, quick: bool, tuned: dict, runs: int, n: int) -> list[Job]:
    """Each cell × each cell_job, then every job (the TOML's rules); ``n``: the sweep's runs, ``tuned``: the scales."""
    cells = [dict(c, **j, key=c["key"] + j["suffix"]) for c in s["cell"] for j in s["cell_job"]]
    out = []
    for j in [j for j in cells + s["job"] if not (quick and j.get("full"))]:
        params = {f: tuned if p == "tuned" else p for f, p in j.get("params", {}).items()}
        k = n if j.get("sweep") else runs
        dataset, data, task = j.get("dataset", s["dataset"]), dict(j.get("data", {})), j.get("task", {})
        out.append(Job(j["key"], dataset, tuple(j["filters"]), data, params, task, min(k, j.get("at_most", k))))
    return out


def tune(s: dict, runs: int, seed: int, data_dir, quiet: bool) -> tuple[dict, str, str]:
    """The UKF's scales by ``[tuning]``'s rule (:func:`.lowest_then_consistent`) on its grid, their label, the table."""
    t, f = s["tuning"], s["tuning"]["filter"]
    points = grid_points(t["grid"])
    grid = [Job(f"tune {p}", s["dataset"], (f,), t["data"], {f: p}, runs=min(runs, t["runs"])) for p in points]
    xs = [ev.rows[0] for ev in evaluate_jobs(grid, runs, seed + t["seed_offset"], data_dir, quiet).values()]
    chosen = lowest_then_consistent(xs, t["tie"], t["anees"])
    if chosen is None:
        raise ReplayError(f"001 tuning: every grid point of the {f.upper()} diverged on the training seeds")
    rows = [[f"{v:g}" for v in p.values()] for p in points]
    rows = [r + [f"{x['pos_rmse']:.3f}", f"{float(x['anees'] or np.nan):.1f}", ""] for r, x in zip(rows, xs)]
    rows[chosen][-1] = "**chosen**"
    return points[chosen], t["label"].format(**points[chosen]), md([*t["grid"], *t["columns"]], rows)


def items(evs: dict, rows: list) -> list[tuple]:
    """``[label, job, filter]`` rows whose jobs ran as (label, (evaluation, index)) over their common first runs."""
    rows = [r for r in rows if r[1] in evs]
    n = min(evs[k].config["runs"] for _, k, _ in rows)
    return [(label, row(evs[k].first(n), f)) for label, k, f in rows]


def comparison(evs: dict, c: dict) -> Comparison:
    """The ``[evidence]`` comparison "fa × a < fb × b" of per-run ``metric``, over the arms' common first runs."""
    arms = items(evs, [["a", *c["a"]], ["b", *c["b"]]])
    (a, la), (b, lb) = (per_run(ev.results[i], c["metric"]) for _, (ev, i) in arms)
    return Comparison(c["name"], c.get("fa", 1.0) * a, c.get("fb", 1.0) * b, la, lb)


def evidence(s: dict, evs: dict) -> dict:
    """Key -> the comparisons of ``[evidence]`` whose two jobs ran (a full-only job's: none in the quick document)."""
    ran = lambda c: c["a"][0] in evs and c["b"][0] in evs
    return {key: [comparison(evs, c) for c in cs if ran(c)] for key, cs in s["evidence"].items()}


def final(ev, i: int, c: dict) -> str:
    """Result ``i``'s mean final estimate of ``[info]`` column ``c`` (:func:`.final_estimate`), formatted."""
    value = final_estimate(ev.results[i].estimates, c["key"], c.get("component"), c.get("abs", False))
    return format(value, c["format"])


def spec_table(s: dict, evs: dict, t: dict) -> str:
    """One ``[[table]]``: its rows' results and commands, then the final estimates (``info``) of its AUKF rows."""
    its, metrics, cols = items(evs, t["rows"]), t["metrics"], s["info"].get(t.get("info"), [])
    out = []
    if metrics:
        rows = combine(its, metrics=metrics)
        out.append(table(rows, metrics=metrics, paired_metrics=t["paired"]) + "\n\nCommands:\n\n" + commands(rows))
    if cols:
        values = [[lab] + [final(ev, i, c) for c in cols] for lab, (ev, i) in its if ev.results[i].name == "aukf"]
        out.append(md(["filter"] + [c["head"] for c in cols], values))
    return "\n\n".join(out)


def nees_row(r: dict) -> list:
    """A leaderboard row's consistency (``nees``): ANEES (its 95 % band), steps inside, flag, ANIS; 0: n/a."""
    v = {k: fmt(float(r.get(k) or np.nan)) for k in ("anees", "anees_lo", "anees_hi", "anees_inside", "anis")}
    band = f"[{v['anees_lo']}, {v['anees_hi']}]"
    return [r["label"], v["anees"], band, v["anees_inside"], r.get("anees_flag", ""), v["anis"]]


def cell(s: dict, evs: dict, key: str, tuned: str) -> list[str]:
    """A cell's RMSE table of its ``cell_rows`` (``tuned``: the tuned UKF's label), its NEES table, its commands."""
    rows = [[label.replace("{tuned}", tuned), key + suffix, f] for label, suffix, f in s["cell_rows"]]
    rows = combine(items(evs, rows), s["metrics"])
    return [table(rows, metrics=s["metrics"]), md(s["nees"], [nees_row(r) for r in rows]), "Commands:", commands(rows)]


def fields(s, evs, verdicts, runs, seed, n, tl, grid_md, quick, doc) -> dict:
    """The template's placeholders (``tl``: the tuned UKF's label): the cells' tables, every ``[[table]]``, figures."""
    primary, nees, _, cmds = cell(s, evs, s["primary"], tl)
    cells = ["\n\n".join([f"### {c['title']}", *cell(s, evs, c["key"], tl)]) for c in s["cell"] if c["key"] in evs]
    relabel = md(s["relabel"], [[v.claim.id, papers.old_labels(s)[v.claim.id], v.label, found(v)] for v in verdicts])
    out = dict(runs=runs, n=n, seed=seed, quick=" --quick" * quick, tuned=tl, grid=grid_md, relabel=relabel)
    out |= dict(primary=primary, nees=nees, commands=cmds, cells="\n\n".join(cells), tune_runs=s["tuning"]["runs"])
    return out | {"plots": plots(s, evs, doc)} | {t["name"]: spec_table(s, evs, t) for t in s["table"]}


def traces_figure(t, estimates: list, tr: dict):
    """The AUKF's noise-mean estimates (``[traces]``, :func:`.history`) over time: median, 5-95 % band of the runs."""
    panels = [(name, unit, history(estimates, key, j)) for key, j, name, unit in tr["panels"]]
    return draw.band_panels(t, panels, colour("aukf"), tr["label"], tr["title"].format(runs=len(estimates)))


def plots(s: dict, evs: dict, doc: Path) -> str:
    """The figures of ``plot`` (:func:`.rmse_figures`) and ``[traces]`` saved beside ``doc``, as Markdown."""
    out, quantities, tr, ev = [], s["quantities"], s["traces"], evs[s["traces"]["job"]]
    doc.parent.mkdir(parents=True, exist_ok=True)
    for fig in s["plot"]:
        errors = {lab: draw.abs_errors(e.results[i].errors, quantities) for lab, (e, i) in items(evs, fig["filters"])}
        figs = draw.rmse_figures(evs[fig["filters"][0][1]].t, errors, quantities, f"001, {fig['title']}")
        for key, name, *_ in quantities:
            draw.save(figs[key], png := doc.parent / f"001_{fig['file']}_{key}.png")
            out += [f"![{name} over time, {fig['track']}]({png.name})", ""]
    draw.save(traces_figure(ev.t, ev.results[0].estimates, tr), doc.parent / "001_traces.png")
    return "\n".join(out + [f"![{tr['alt']}](001_traces.png)", "", f"{tr['text']}`{command(ev)}`.", ""])


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False, sweep_runs=None):
    """Write ``docs/reproduction/001.md``: ``runs`` Monte Carlo runs (the TOML's ``runs``; quick:
    ``quick_runs``) for the main tables, ``sweep_runs`` (at most ``runs``) for the sweep and the ablation."""
    watch, s, doc = Stopwatch(), load(), Path(doc or "docs/reproduction/001.md")
    runs = runs or s["quick_runs" if quick else "runs"]
    n = min(sweep_runs or s["sweep_runs"], runs)
    tuned, label, grid_md = tune(s, runs, seed, data_dir, quiet)
    evs = evaluate_jobs(jobs(s, quick, tuned, runs, n), runs, seed, data_dir, quiet)
    verdicts = decide(papers.claims(s, "001.toml"), evidence(s, evs), seed=seed)
    text = render("001", fields(s, evs, verdicts, runs, seed, n, label, grid_md, quick, doc), verdicts)
    command_line = f"replay reproduce 001 --runs {runs} --seed {seed}" + " --quick" * quick
    write_document(doc, text + footer(command_line, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
