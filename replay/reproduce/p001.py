"""Reproduction of paper 001 (AUKF vs UKF, small-AUV dead reckoning in currents), §5 Fig. 3–5.

The paper publishes figures only: per-time RMSE of north, east, depth, body velocity and
acceleration for UKF and AUKF. Everything declared is data in ``replay/papers/001.toml`` (the
experiments, the UKF's tuning grid and rule, the tables, the comparisons the claims draw on, the
claims with their rules (:mod:`.spec`) and old labels, the figures); the prose is
``replay/papers/001.md``, filled by the one renderer (:mod:`.render`). Every row comes from
:func:`replay.run.evaluation.evaluate` (the pipeline of ``replay eval``), comparisons paired on the
same runs (common random numbers). Everything the paper does not print (time step, Q, R, P0, mission
legs, current scale, DVL mode) is documented in replay/sim/sauv_current.py and replay/models/sauv.py.

Reading rules of the TOML (every key checked against :data:`SCHEMA`: an unknown or a missing one is
refused naming the file and the entry, as is a job named but not planned):

* jobs (:func:`jobs`): each ``cell`` runs every ``cell_job`` (key: the cell's key + the suffix), then
  every ``job``; ``runs = "sweep"``: the sweep's runs, ``at_most``: a cap, ``full``: not in the quick
  document; a filter's parameters ``"tuned"``: the scales :func:`pick` chose on the ``[tuning]`` grid
  (every combination of its lists, in order), run on seed + ``seed_offset``;
* tables and comparisons name ``[job, filter]`` and are made over the common first runs of their
  jobs (the sweep's runs: the first runs of the main tables); an entry whose job is full-only is left
  out of the quick document.

Adding an ablation is a TOML edit: a ``job``, a row in its ``[[table]]`` (and a comparison in
``[evidence]`` when a claim draws on it); a claim: a ``[[claim]]`` whose rule names evidence keys.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from replay.util.errors import ReplayError

from . import spec as papers
from .common5 import Job, combine, command, commands, rmse_figures, row, run_jobs, table
from .render import found, render, table as md
from .rules import Comparison, decide, per_run
from .verdict import Stopwatch, footer, write_document

SCHEMA = {  # kind of entry -> (required keys, optional keys)
    "top level": ("dataset runs quick_runs sweep_runs primary metrics cell cell_job cell_rows job tuning table", ""),
    "top level ": ("info evidence plots claim", ""),
    "tuning": ("filter data grid runs seed_offset tie anees label", ""),
    "cell": ("key title data", "full"),
    "cell_job": ("suffix filters", "params"),
    "job": ("key filters", "dataset data params task runs at_most full"),
    "table": ("name metrics paired rows", "info"),
    "info": ("head key format", "component abs"),
    "evidence": ("name metric a b", "fa fb"),
    "plots": ("quantities plot traces", ""),
    "plot": ("file track title filters", ""),
    "traces": ("job label panels title alt text", ""),
}


def check(entry: dict, kinds: tuple, name: str) -> None:
    """ValueError naming ``name`` unless ``entry``'s keys are those of :data:`SCHEMA` ``[kinds]``."""
    req, opt = (set(" ".join(SCHEMA[k][j] for k in kinds).split()) for j in (0, 1))
    bad, missing = set(entry) - req - opt, req - set(entry)
    if bad or missing or entry.get("runs", "sweep") != "sweep" and "filters" in entry:
        what = f"unknown key(s) {sorted(bad)}" if bad else f"missing {sorted(missing)}" if missing else "runs: 'sweep'"
        raise ValueError(f"001.toml: {name}: {what}")


def load() -> dict:
    """``replay/papers/001.toml``, every entry checked (module docstring), the claims read by :mod:`.spec`."""
    s = papers.load("001")
    check(s, ("top level", "top level "), "top level")
    for kind, e in [("tuning", s["tuning"]), ("plots", s["plots"]), ("traces", s["plots"]["traces"])]:
        check(e, (kind,), f"[{kind}]")
    named = [(k, x) for k in ("cell", "cell_job", "job", "table") for x in s[k]] + [
        ("plot", x) for x in s["plots"]["plot"]
    ]
    named += [(k, x) for sect in ("info", "evidence") for xs in s[sect].values() for k, x in zip([sect] * len(xs), xs)]
    for i, (kind, e) in enumerate(named):
        check(e, (kind,), f"{kind} {next((e[k] for k in ('key', 'name', 'file', 'head', 'suffix') if k in e), i)!r}")
    planned = {j.key for j in jobs(s, False, {}, 1, 1)}
    refs = [(f"table {t['name']!r}", r[1]) for t in s["table"] for r in t["rows"]] + [("primary", s["primary"])]
    refs += [(f"evidence {c['name']!r}", c[x][0]) for cs in s["evidence"].values() for c in cs for x in "ab"]
    refs += [(f"plot {p['file']!r}", f[1]) for p in s["plots"]["plot"] for f in p["filters"]]
    for where, key in refs + [("[plots.traces]", s["plots"]["traces"]["job"])]:
        if key not in planned:
            raise ValueError(f"001.toml: {where}: no job {key!r} is planned")
    papers.claims(s, "001.toml")
    return s


def jobs(s: dict, quick: bool, tuned: dict, runs: int, n: int) -> list[Job]:
    """Every scored evaluation (module docstring; ``n``: the sweep's runs; ``tuned``: the chosen scales)."""
    cells = [
        dict(j, key=c["key"] + j["suffix"], data=c["data"], full=c.get("full"))
        for c in s["cell"]
        for j in s["cell_job"]
    ]
    out = []
    for j in [j for j in cells + s["job"] if not (quick and j.get("full"))]:
        k = n if j.get("runs") == "sweep" else runs
        params = {f: tuned if p == "tuned" else p for f, p in j.get("params", {}).items()}
        data = dict(j.get("data", {}))
        out.append(
            Job(
                j["key"],
                j.get("dataset", s["dataset"]),
                tuple(j["filters"]),
                data,
                params,
                j.get("task", {}),
                min(k, j.get("at_most", k)),
            )
        )
    return out


def grid(s: dict) -> list[dict]:
    """The tuning grid's points: every combination of ``[tuning] grid``'s lists, in their order."""
    g = s["tuning"]["grid"]
    return [dict(zip(g, v)) for v in itertools.product(*g.values())]


def tuning_jobs(s: dict, runs: int) -> list[Job]:
    t = s["tuning"]
    return [
        Job(f"tune {p}", s["dataset"], (t["filter"],), t["data"], {t["filter"]: p}, runs=min(runs, t["runs"]))
        for p in grid(s)
    ]


def pick(s: dict, evs: dict) -> tuple[dict, str]:
    """The tuned baseline's scales by the declared rule (``[tuning]``: the lowest mean position RMSE, a
    diverged point scoring inf as in ``replay tune``; within ``tie`` of it the ANEES closest to ``anees``)
    and the grid's table."""
    t, pts = s["tuning"], [(p, evs[f"tune {p}"].rows[0]) for p in grid(s)]
    score = [x["pos_rmse"] if not x.get("diverged") and np.isfinite(float(x["pos_rmse"])) else np.inf for _, x in pts]
    if not np.isfinite(best := min(score)):
        raise ReplayError(f"001 tuning: every grid point of the {t['filter'].upper()} diverged on the training seeds")
    near = [pt for pt, sc in zip(pts, score) if sc <= (1 + t["tie"]) * best]
    chosen = min(near, key=lambda pt: abs(float(pt[1]["anees"] or np.inf) - t["anees"]))[0]
    rows = [
        [
            *(f"{v:g}" for v in p.values()),
            f"{x['pos_rmse']:.3f}",
            f"{float(x['anees'] or np.nan):.1f}",
            "**chosen**" if p == chosen else "",
        ]
        for p, x in pts
    ]
    return chosen, md([*t["grid"], "pos_rmse (training seeds)", "ANEES", ""], rows)


def evidence(s: dict, evs: dict) -> dict:
    """Key -> the comparisons "fa × a < fb × b" of ``[evidence]`` whose jobs ran, over their common first runs."""
    out = {}
    for key, cs in s["evidence"].items():
        out[key] = []
        for c in [c for c in cs if c["a"][0] in evs and c["b"][0] in evs]:
            (a, la), (b, lb) = (per_run(evs[j].results[row(evs[j], f)[1]], c["metric"]) for j, f in (c["a"], c["b"]))
            m = min(len(a), len(b))
            out[key].append(Comparison(c["name"], c.get("fa", 1.0) * a[:m], c.get("fb", 1.0) * b[:m], la[:m], lb[:m]))
    return out


def items(evs: dict, rows: list) -> list[tuple]:
    """``[label, job, filter]`` rows whose jobs ran as (label, (evaluation, index)) over their common first runs."""
    rows = [r for r in rows if r[1] in evs]
    n = min(evs[k].config["runs"] for _, k, _ in rows)
    return [(label, row(evs[k].first(n), f)) for label, k, f in rows]


def nees_table(rows) -> str:
    f = lambda r, k: f"{float(r[k]):.3g}" if np.isfinite(float(r.get(k) or np.nan)) else "n/a"  # noqa: E731
    return md(
        ["filter", "ANEES (position, 3 dof)", "95 % band", "steps inside", "flag", "ANIS"],
        [
            [
                r["label"],
                f(r, "anees"),
                f"[{f(r, 'anees_lo')}, {f(r, 'anees_hi')}]",
                f(r, "anees_inside"),
                r.get("anees_flag", ""),
                f(r, "anis"),
            ]
            for r in rows
        ],
    )


def final(ev, i: int, c: dict) -> float:
    """Mean over runs of the final estimate ``c["key"]`` of result ``i`` (a matrix: its diagonal): its
    ``component``, else the mean over its components; ``abs``: of the magnitudes."""
    v = [np.atleast_1d(np.asarray(e.info[c["key"]], float)) for e in ev.results[i].estimates]
    v = [np.abs(x) if c.get("abs") else x for x in (np.diagonal(x) if x.ndim == 2 else x for x in v)]
    return float(np.mean([x[c["component"]] if "component" in c else x.mean() for x in v]))


def spec_table(s: dict, evs: dict, t: dict) -> str:
    """One ``[[table]]``: its rows' results and commands, then the final estimates of its AUKF rows."""
    its = items(evs, t["rows"])
    out = []
    if t["metrics"]:
        rows = combine(its, metrics=t["metrics"])
        out.append(table(rows, metrics=t["metrics"], paired_metrics=t["paired"]) + "\n\nCommands:\n\n" + commands(rows))
    if cols := s["info"].get(t.get("info"), []):
        est = [(label, ev, i) for label, (ev, i) in its if ev.results[i].name == "aukf"]
        out.append(
            md(
                ["filter"] + [c["head"] for c in cols],
                [[lab] + [format(final(ev, i, c), c["format"]) for c in cols] for lab, ev, i in est],
            )
        )
    return "\n\n".join(out)


def fields(s, evs, verdicts, runs, seed, n, tuned, grid_md, quick, doc) -> dict:
    """The template's placeholders."""
    tl = s["tuning"]["label"].format(**tuned)

    def cell(key):  # a cell's table, its NEES table and its commands
        r = combine(
            items(evs, [[lab.replace("{tuned}", tl), key + suf, f] for lab, suf, f in s["cell_rows"]]),
            metrics=s["metrics"],
        )
        return table(r, metrics=s["metrics"]), nees_table(r), commands(r)

    (primary, nees, cmds), old = cell(s["primary"]), papers.old_labels(s)
    cells = [
        "\n\n".join([f"### {c['title']}", t, e, "Commands:", x])
        for c in s["cell"]
        if c["key"] in evs
        for t, e, x in [cell(c["key"])]
    ]
    relabel = [[v.claim.id, old[v.claim.id], v.label, found(v)] for v in verdicts]
    return {
        "runs": runs,
        "n": n,
        "tuned": tl,
        "grid": grid_md,
        "tune_runs": s["tuning"]["runs"],
        "primary": primary,
        "nees": nees,
        "commands": cmds,
        "cells": "\n\n".join(cells),
        "relabel": md(["claim", "old label", "new label", "the numbers behind it"], relabel),
        "quick": " --quick" if quick else "",
        "seed": seed,
        "plots": plots(s["plots"], evs, doc),
    } | {t["name"]: spec_table(s, evs, t) for t in s["table"]}


def run_errors(ev, i: int, quantities: list) -> dict[str, np.ndarray]:
    """Per-run absolute errors (runs, steps) of result ``i``: per quantity [key, name, unit, error, column]."""
    errs = ev.results[i].errors
    out = {q[0]: np.abs(np.stack([np.asarray(x[q[3]], float) for x in errs])) for q in quantities}
    return {q[0]: out[q[0]][:, :, q[4]] if len(q) > 4 else out[q[0]] for q in quantities}


def traces_figure(t, histories: list[dict], tr: dict):
    """The AUKF's noise-mean estimates over time (``[plots.traces]``): median and 5-95 % band over the runs."""
    from replay.outputs import plots
    from replay.outputs.palette import colour

    fig, axes = plots.figure(len(tr["panels"]), 1, figsize=(8, 2.1 * len(tr["panels"]) + 0.6), sharex=True)
    for ax, (key, j, name, unit) in zip(axes[:, 0], tr["panels"]):
        v = np.stack([np.asarray(h[key], float)[:, j] for h in histories])
        plots.mc_band(ax, t[-v.shape[1] :], v, colour("aukf"), tr["label"])
        ax.set_ylabel(plots.label(name, unit))
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper left")
    axes[-1, 0].set_xlabel("t (s)")
    plots.suptitle(fig, tr["title"].format(runs=len(histories)))
    fig.subplots_adjust(hspace=0.15)
    return fig


def plots(p: dict, evs: dict, doc: Path) -> str:
    """The figures of ``[plots]`` saved beside ``doc`` (:func:`.common5.rmse_figures`), as Markdown."""
    out, tr = [], p["traces"]
    try:
        from replay.outputs.plots import save

        doc.parent.mkdir(parents=True, exist_ok=True)
        for fig in p["plot"]:
            errors = {lab: run_errors(*row(evs[k], f), p["quantities"]) for lab, k, f in fig["filters"]}
            figs = rmse_figures(
                evs[fig["filters"][0][1]].t, errors, [q[:3] for q in p["quantities"]], f"001, {fig['title']}"
            )
            for key, name, *_ in p["quantities"]:
                save(figs[key], png := doc.parent / f"001_{fig['file']}_{key}.png")
                out += [f"![{name} over time, {fig['track']}]({png.name})", ""]
        ev = evs[tr["job"]]
        save(
            traces_figure(ev.t, [e.info["history"] for e in ev.results[0].estimates], tr),
            png := doc.parent / "001_traces.png",
        )
        out += [f"![{tr['alt']}]({png.name})", "", f"{tr['text']}`{command(ev)}`.", ""]
    except ImportError:
        out += ["(plots skipped: matplotlib is not installed)", ""]
    return "\n".join(out)


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False, sweep_runs=None):
    """Write ``docs/reproduction/001.md``: ``runs`` Monte Carlo runs (the TOML's ``runs``; quick:
    ``quick_runs``) for the main tables, ``sweep_runs`` (at most ``runs``) for the sweep and the ablation."""
    watch, s = Stopwatch(), load()
    runs = runs or s["quick_runs" if quick else "runs"]
    n = min(sweep_runs or s["sweep_runs"], runs)
    doc = Path(doc or "docs/reproduction/001.md")
    tuned, grid_md = pick(s, run_jobs(tuning_jobs(s, runs), runs, seed + s["tuning"]["seed_offset"], data_dir, quiet))
    evs = run_jobs(jobs(s, quick, tuned, runs, n), runs, seed, data_dir, quiet)
    verdicts = decide(papers.claims(s, "001.toml"), evidence(s, evs), seed=seed)
    text = render("001", fields(s, evs, verdicts, runs, seed, n, tuned, grid_md, quick, doc), verdicts)
    command_line = f"replay reproduce 001 --runs {runs} --seed {seed}" + (" --quick" if quick else "")
    write_document(doc, text + footer(command_line, watch.seconds))
    if not quiet:
        print(f"wrote {doc} in {watch.seconds:.0f} s")
    return evs
