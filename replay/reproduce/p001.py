"""Reproduction of paper 001 (AUKF vs UKF, small-AUV dead reckoning in currents), §5 Fig. 3–5: the paper prints
figures only (per-time RMSE of north, east, depth, body velocity and acceleration of UKF and AUKF).

Everything declared (experiments, the UKF's tuning grid and rule, tables, the comparisons the claims draw on, the
claims with their rules (:mod:`.spec`), figures) is data in ``replay/papers/001.toml``, whose comments give its
reading rules; :func:`load` refuses an unknown or missing key (:data:`SCHEMA`) and a job or info list named but not
declared. The prose is ``replay/papers/001.md`` (:mod:`.render`). Adding an ablation is a TOML edit: a ``job``, a
row in its ``[[table]]`` (and a comparison in ``[evidence]`` if a claim draws on it); a claim: a ``[[claim]]``.
"""

import itertools
from pathlib import Path

import numpy as np

from replay.campaign.longest import Job, evaluate_jobs
from replay.outputs import plots as draw
from replay.outputs.palette import colour
from replay.outputs.plots import rmse_figures
from replay.util.errors import ReplayError
from replay.util.portable import write_document

from . import spec as papers
from .render import found, render
from .render import table as md
from .rules import Comparison, decide, per_run
from .tables import Stopwatch, combine, command, commands, footer, row, table

SCHEMA = {  # kind of entry -> its keys ("key?": optional; :func:`check`)
    "top level": "dataset runs quick_runs sweep_runs primary metrics cell cell_job cell_rows job quantities plot "
    "tuning table info evidence traces nees claim",
    "tuning": "filter data grid runs seed_offset tie anees label",
    "cell": "key title data full?",
    "cell_job": "suffix filters params?",
    "job": "key filters dataset? data? params? task? sweep? at_most? full?",
    "table": "name metrics paired rows info?",
    "info": "head key format component? abs?",
    "evidence": "name metric a b fa? fb?",
    "plot": "file track title filters",
    "traces": "job label panels title alt text",
}


def check(entry: dict, kind: str, name="") -> dict:
    """``entry``, or a ValueError naming the file and the entry unless its keys are :data:`SCHEMA`'s ``kind``."""
    return papers.check(entry, SCHEMA[kind], f"001.toml: {kind}{f' {name!r}' if name else ''}")


def load() -> dict:
    """``replay/papers/001.toml``, every entry checked (module docstring); the claims by :mod:`.spec`."""
    s = check(papers.load("001"), "top level")
    entries = [("tuning", s["tuning"]), ("traces", s["traces"])]
    entries += [(k, x) for k in ("cell", "cell_job", "job", "table", "plot") for x in s[k]]
    entries += [(k, x) for k in ("info", "evidence") for xs in s[k].values() for x in xs]
    for kind, e in entries:
        check(e, kind, next((e[k] for k in ("key", "name", "file", "head", "suffix", "job") if k in e), ""))
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
    for j in (j for j in cells + s["job"] if not (quick and j.get("full"))):
        params = {f: tuned if p == "tuned" else p for f, p in j.get("params", {}).items()}
        ds, data, k = j.get("dataset", s["dataset"]), dict(j.get("data", {})), n if j.get("sweep") else runs
        out.append(Job(j["key"], ds, tuple(j["filters"]), data, params, j.get("task", {}), min(k, j.get("at_most", k))))
    return out


def tune(s: dict, runs: int, seed: int, data_dir, quiet: bool) -> tuple[dict, str]:
    """The baseline's scales chosen by ``[tuning]``'s rule on its grid (every combination of its lists), its table."""
    t, f = s["tuning"], s["tuning"]["filter"]
    points = [dict(zip(t["grid"], v)) for v in itertools.product(*t["grid"].values())]
    grid = [Job(f"tune {p}", s["dataset"], (f,), t["data"], {f: p}, runs=min(runs, t["runs"])) for p in points]
    xs = [ev.rows[0] for ev in evaluate_jobs(grid, runs, seed + t["seed_offset"], data_dir, quiet).values()]
    score = [x["pos_rmse"] if not x.get("diverged") and np.isfinite(float(x["pos_rmse"])) else np.inf for x in xs]
    if not np.isfinite(best := min(score)):
        raise ReplayError(f"001 tuning: every grid point of the {f.upper()} diverged on the training seeds")
    near = [(p, x) for p, x, sc in zip(points, xs, score) if sc <= (1 + t["tie"]) * best]
    chosen = min(near, key=lambda pt: abs(float(pt[1]["anees"] or np.inf) - t["anees"]))[0]
    anees = [f"{float(x['anees'] or np.nan):.1f}" for x in xs]
    rows = [[*map("{:g}".format, p.values()), f"{x['pos_rmse']:.3f}", a] for p, x, a in zip(points, xs, anees)]
    rows = [r + ["**chosen**" * (p == chosen)] for r, p in zip(rows, points)]
    return chosen, md([*t["grid"], "pos_rmse (training seeds)", "ANEES", ""], rows)


def items(evs: dict, rows: list) -> list[tuple]:
    """``[label, job, filter]`` rows whose jobs ran as (label, (evaluation, index)) over their common first runs."""
    rows = [r for r in rows if r[1] in evs]
    n = min(evs[k].config["runs"] for _, k, _ in rows)
    return [(label, row(evs[k].first(n), f)) for label, k, f in rows]


def evidence(s: dict, evs: dict) -> dict:
    """Key -> the comparisons "fa × a < fb × b" of ``[evidence]`` whose jobs ran, over their common first runs."""
    out = {}
    for key, c in ((key, c) for key, cs in s["evidence"].items() for c in cs if c["a"][0] in evs and c["b"][0] in evs):
        arms = items(evs, [["a", *c["a"]], ["b", *c["b"]]])
        (a, la), (b, lb) = (per_run(ev.results[i], c["metric"]) for _, (ev, i) in arms)
        out.setdefault(key, []).append(Comparison(c["name"], c.get("fa", 1.0) * a, c.get("fb", 1.0) * b, la, lb))
    return out


def final(ev, i: int, c: dict) -> str:
    """Mean over runs of result ``i``'s final estimate of ``[info]`` column ``c`` (a matrix: its diagonal)."""
    v = [np.atleast_1d(np.asarray(e.info[c["key"]], float)) for e in ev.results[i].estimates]
    v = [np.abs(x) if c.get("abs") else x for x in (np.diagonal(x) if x.ndim == 2 else x for x in v)]
    return format(float(np.mean([x[c["component"]] if "component" in c else x.mean() for x in v])), c["format"])


def spec_table(s: dict, evs: dict, t: dict) -> str:
    """One ``[[table]]``: its rows' results and commands, then the final estimates (``info``) of its AUKF rows."""
    its, m, cols = items(evs, t["rows"]), t["metrics"], s["info"].get(t.get("info"), [])
    rows = combine(its, metrics=m) if m else []
    out = [table(rows, metrics=m, paired_metrics=t["paired"]) + "\n\nCommands:\n\n" + commands(rows)] if m else []
    values = [[lab] + [final(ev, i, c) for c in cols] for lab, (ev, i) in its if ev.results[i].name == "aukf"]
    return "\n\n".join(out + [md(["filter"] + [c["head"] for c in cols], values)] * bool(cols))


def fields(s, evs, verdicts, runs, seed, n, tuned, grid_md, quick, doc) -> dict:
    """The template's placeholders: the cells' tables (``cell_rows``), every ``[[table]]``, the figures."""
    tl, old = s["tuning"]["label"].format(**tuned), papers.old_labels(s)
    g = lambda r, k: f"{float(r[k]):.3g}" if np.isfinite(float(r.get(k) or np.nan)) else "n/a"  # noqa: E731

    def cell(key):  # a cell's table, its NEES table (ANEES against its 95 % band, steps inside, ANIS), commands
        rows = [[lab.replace("{tuned}", tl), key + x, f] for lab, x, f in s["cell_rows"]]
        r = combine(items(evs, rows), s["metrics"])
        band = [[x["label"], g(x, "anees"), f"[{g(x, 'anees_lo')}, {g(x, 'anees_hi')}]"] for x in r]
        band = [b + [g(x, "anees_inside"), x.get("anees_flag", ""), g(x, "anis")] for b, x in zip(band, r)]
        return [table(r, metrics=s["metrics"]), md(s["nees"], band), "Commands:", commands(r)]

    primary, nees, _, cmds = cell(s["primary"])
    cells = "\n\n".join("\n\n".join([f"### {c['title']}", *cell(c["key"])]) for c in s["cell"] if c["key"] in evs)
    out = dict(runs=runs, n=n, seed=seed, quick=" --quick" * quick, tuned=tl, grid=grid_md, cells=cells)
    out |= dict(tune_runs=s["tuning"]["runs"], primary=primary, nees=nees, commands=cmds, plots=plots(s, evs, doc))
    relabel = [[v.claim.id, old[v.claim.id], v.label, found(v)] for v in verdicts]
    out["relabel"] = md(["claim", "old label", "new label", "the numbers behind it"], relabel)
    return out | {t["name"]: spec_table(s, evs, t) for t in s["table"]}


def run_errors(ev, i: int, quantities: list) -> dict[str, np.ndarray]:
    """Per-run absolute errors (runs, steps) of result ``i`` per quantity ``[key, name, unit, error, column]``."""
    e = {q[0]: np.abs(np.stack([np.asarray(x[q[3]], float) for x in ev.results[i].errors])) for q in quantities}
    return {q[0]: e[q[0]][:, :, q[4]] if len(q) > 4 else e[q[0]] for q in quantities}


def traces_figure(t, histories: list[dict], tr: dict):
    """The AUKF's noise-mean estimates over time (``[traces]``): median and 5-95 % band over the runs."""
    fig, axes = draw.figure(len(tr["panels"]), 1, figsize=(8, 2.1 * len(tr["panels"]) + 0.6), sharex=True)
    for ax, (key, j, name, unit) in zip(axes[:, 0], tr["panels"]):
        v = np.stack([np.asarray(h[key], float)[:, j] for h in histories])
        draw.mc_band(ax, t[-v.shape[1] :], v, colour("aukf"), tr["label"])
        ax.set_ylabel(draw.label(name, unit))
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper left")
    axes[-1, 0].set_xlabel("t (s)")
    draw.suptitle(fig, tr["title"].format(runs=len(histories)))
    fig.subplots_adjust(hspace=0.15)
    return fig


def plots(s: dict, evs: dict, doc: Path) -> str:
    """The figures of ``plot`` and ``[traces]`` saved beside ``doc`` (:func:`.common5.rmse_figures`), as Markdown."""
    out, quantities, tr, ev = [], [q[:3] for q in s["quantities"]], s["traces"], evs[s["traces"]["job"]]
    doc.parent.mkdir(parents=True, exist_ok=True)
    for fig in s["plot"]:
        errors = {lab: run_errors(*row(evs[k], f), s["quantities"]) for lab, k, f in fig["filters"]}
        figs = rmse_figures(evs[fig["filters"][0][1]].t, errors, quantities, f"001, {fig['title']}")
        for key, name, _ in quantities:
            draw.save(figs[key], png := doc.parent / f"001_{fig['file']}_{key}.png")
            out += [f"![{name} over time, {fig['track']}]({png.name})", ""]
    histories = [e.info["history"] for e in ev.results[0].estimates]
    draw.save(traces_figure(ev.t, histories, tr), doc.parent / "001_traces.png")
    return "\n".join(out + [f"![{tr['alt']}](001_traces.png)", "", f"{tr['text']}`{command(ev)}`.", ""])


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False, sweep_runs=None):
    """Write ``docs/reproduction/001.md``: ``runs`` Monte Carlo runs (the TOML's ``runs``; quick:
    ``quick_runs``) for the main tables, ``sweep_runs`` (at most ``runs``) for the sweep and the ablation."""
    watch, s, doc = Stopwatch(), load(), Path(doc or "docs/reproduction/001.md")
    runs = runs or s["quick_runs" if quick else "runs"]
    n = min(sweep_runs or s["sweep_runs"], runs)
    tuned, grid_md = tune(s, runs, seed, data_dir, quiet)
    evs = evaluate_jobs(jobs(s, quick, tuned, runs, n), runs, seed, data_dir, quiet)
    verdicts = decide(papers.claims(s, "001.toml"), evidence(s, evs), seed=seed)
    text = render("001", fields(s, evs, verdicts, runs, seed, n, tuned, grid_md, quick, doc), verdicts)
    command_line = f"replay reproduce 001 --runs {runs} --seed {seed}" + " --quick" * quick
    write_document(doc, text + footer(command_line, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
