"""``python -m replay.reproduce.fusion_doc``: writes ``docs/fusion.md``, the fusion results of every shared
recording with sensors (issue 35 item 7).

Per recording: where its reference comes from; the outage / resurfacing protocol at the filters' defaults
(:mod:`replay.tasks.outages`: the error at the first fix after each outage, withheld from every filter,
against hold-last-fix and the recorded onboard estimate where the recording has one); each filter at its
defaults and tuned (:mod:`replay.tune.repeat`: ``--trials`` per tune, ``--repeats`` tunes, the first 60 %
tuned on, the rest scored, intervals over tunes x runs) beside the fed position sensor alone (the
``measurements`` row: the fixes, held between); and which filter is best and by how much, or that the
recording cannot decide it. Every number is computed by the command; the tunes and evaluations are kept in
``--work`` (a rerun resumes them).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from replay.run.eval_options import EvalOptions
from replay.run.evaluation import evaluate
from replay.scoring import outages
from replay.tune import check, repeat
from replay.tune.options import TuneOptions
from replay.util.errors import ReplayError
from replay.util.files import write_atomic

WINDOWS = {"outage": 30.0, "outage_every": 90.0}  # withheld windows where the recording has no outage of its own
BOHAI_REF = (
    "the vehicle's own navigation solution (the log's lat/lon, an onboard INS/GPS product, jumps masked): "
    "at the surface it follows the GPS fixes the filters are fed, after a dive it is the vehicle's own "
    "dead reckoning; it shares a source with the fed GPS"
)
TEST1_REF = (
    "the GPS fix topic /fix itself: every 5th fix is fed, the others are the reference (a fed sensor's "
    "neighbours: the GPS errors are strongly time-correlated, so the held-out fixes favour a track that "
    "follows the fed ones)"
)
RECORDINGS = [
    dict(id="bohai/20220822_0_3", ref=BOHAI_REF, outage=WINDOWS, what="surface run, fixes ~1 Hz"),
    dict(id="bohai/20220822_0_4", ref=BOHAI_REF, outage={}, what="dives (its own outages: 13-660 s)"),
    dict(id="bohai/20220822_0_5", ref=BOHAI_REF, outage=WINDOWS, what="mostly surface"),
    dict(id="bohai/20220822_0_6", ref=BOHAI_REF, outage={}, what="dives with surfacing fixes"),
    dict(id="bohai/20220625_0_0", ref=BOHAI_REF, outage=WINDOWS, what="lake trial"),
    dict(
        id="BAGS/robot_localization/test1.bag",
        mapping="docs/mappings/rl_test1_fusion.toml",
        ref=TEST1_REF,
        outage=WINDOWS,
        what="Husky ground robot, IMU + wheel odometry + GPS",
    ),
]
NOT_RUN = [
    "bohai/20220822_0_0: not run: its gyro column is dropped by the adapter and the fusion task refuses "
    "the recording (no field 'gyro')"
]


def _dataset(rec, bags_dir):
    return rec["id"].replace("BAGS", str(bags_dir)) if bags_dir else rec["id"]


def _dparams(rec, root):
    return {"mapping": str((root / rec["mapping"]).resolve())} if rec.get("mapping") else {}


def outage_result(rec, filters, runs, data_dir, bags_dir, root) -> dict:
    """The outage protocol at defaults: headline rows and each filter against hold-last-fix."""
    options = EvalOptions(
        task="fusion",
        filters=list(filters),
        runs=runs,
        data_dir=data_dir,
        recorded=None,  # every recorded estimate (the onboard one), scored at the same fixes
        dataset_params=_dparams(rec, root) or None,
        task_params={"score": "outages", **rec["outage"]},
    )
    ev = evaluate(_dataset(rec, bags_dir), options)
    events, heads = outages.tables(ev)
    names = [h["filter"] for h in heads]
    vs = {f: outages.paired(ev, f, "measurements") for f in names if f != "measurements" and "measurements" in names}
    pairs = [
        dict(zip(("a", "b", "difference", "ci95", "different"), (a, b, *outages.paired(ev, a, b))))
        for a in filters
        for b in filters
        if a != b
    ]
    return {"heads": heads, "vs_hold": vs, "pairs": pairs, "events": events}


def tuned_result(rec, filters, trials, repeats, runs, data_dir, bags_dir, root, work) -> dict:
    t = check.prepare(
        TuneOptions(
            dataset=_dataset(rec, bags_dir),
            filters=list(filters),
            entries=repeat.default_space(filters),
            trials=trials,
            objective="mean_rmse",
            runs=runs,
            seed=0,
            task="fusion",
            dataset_params=_dparams(rec, root),
            data_dir=data_dir,
            train_segment="0.6",
        )
    )
    res = repeat.run_repeats(t, work, repeats, quiet=True)
    return {"rows": res["rows"], "pairs": res["pairs"]}


def _f(x, nd=2) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


def verdict(pairs, rows, score="pos_rmse", unit="held-out difference over tunes x runs") -> str:
    tuned = sorted((r for r in rows if r.get("kind", "tuned") == "tuned"), key=lambda r: r[score])
    if any(r.get("still") for r in tuned):
        return (
            "the recording cannot decide: on the held-out part the estimates of "
            + ", ".join(r["filter"] for r in tuned if r.get("still"))
            + " never move (no input there moves them): their error is the start's, not a filter's"
        )
    if len(tuned) < 2:
        return "one filter: nothing to rank"
    best = tuned[0]["filter"]
    diffs = [p for p in pairs if p["a"] == best]
    won = [f"{-p['difference']:.3f} ± {p['ci95']:.3f} m below {p['b']}" for p in diffs if p["different"]]
    tied = [p["b"] for p in diffs if not p["different"]]
    if not tied:
        return f"**{best}** is best: " + ", ".join(won)
    return (
        f"the recording cannot decide between {best} and {', '.join(tied)} (the interval of their {unit} "
        "includes zero)" + (f"; {best} is " + ", ".join(won) if won else "")
    )


def _per_event(o) -> list:
    """Each outage of the recording: its span and every row's end-of-outage error (± over runs where > 1)."""
    names = [h["filter"] for h in o["heads"]]
    by = {(e["filter"], e["event"]): e for e in o["events"]}
    out = ["", "Per outage (m):", "", "| outage | start–end (s) | " + " | ".join(names) + " |"]
    out.append("|---" * (len(names) + 2) + "|")
    for k in sorted({e["event"] for e in o["events"]}):
        first = by[(names[0], k)]
        cells = []
        for n in names:
            e = by[(n, k)]
            ci = e["error_ci95"]
            cells.append(_f(e["error"], 1) + (f" ± {ci:.1f}" if ci is not None and np.isfinite(ci) and ci > 0 else ""))
        out.append(f"| {k} | {first['start_s']:.0f}–{first['end_s']:.0f} | " + " | ".join(cells) + " |")
    return out


def render(results, settings) -> str:
    lines = [
        "# Fusion on the shared recordings",
        "",
        "Generated by `" + settings["command"] + "` (" + settings["budget"] + "); do not edit by hand.",
        "",
        "Two protocols per recording. **Outage / resurfacing** (`--task-param score=outages`,",
        "`replay/tasks/outages.py`): the fixes of each outage (a dive; or, where the recording has none, the last",
        f"{WINDOWS['outage']:g} s of every {WINDOWS['outage_every']:g} s) and the first fix after it are withheld "
        "from every filter; each filter, and a recorded onboard estimate where the recording has one, is",
        "scored at that first fix, against it: the end-of-outage error, mean over events ± its 95 % interval",
        "across events, at the filters' defaults. *hold last fix* is the `measurements` row there. This",
        "reference is a fix no filter has seen. **Tuned** (`replay eval --tune`, `replay/tune/repeat.py`): each",
        "filter's declared noise tuned on the first 60 % against the recording's reference, scored on the rest;",
        "± is the 95 % interval over tunes x runs; *fixes alone* is the fed GPS held between fixes; *still*: the",
        "estimate never moves on the held-out part (no input there moves it), so its error is the start's. The",
        "held-out fixes of the default protocol sit next to fed ones, and GPS errors are time-correlated: an",
        "interval across them would be far too narrow, so per-event intervals are given for outages only.",
        "Bohai has no recorded onboard estimate besides its navigation solution, which is its reference.",
        "The best single sensor alone: the GPS (*fixes alone*, *hold last fix*); gyro and attitude alone give no",
        "position; test1.bag's wheel odometry integrated onboard is its `recorded:wheel_odometry` row.",
        "",
    ]
    for rec, res in results:
        lines += [f"## {rec['id'].replace('BAGS/', 'bags/')}", "", f"{rec['what']}. Reference: {rec['ref']}.", ""]
        if "error" in res:
            lines += [f"Not computed: {res['error']}", ""]
            continue
        lines += _outage_section(rec, res["outages"]) + _tuned_section(res["tuned"])
    lines += ["## Not run", ""] + [f"- {x}" for x in NOT_RUN] + [""]
    return "\n".join(lines)


def _outage_section(rec, o) -> list:
    own = "its own outages (gaps > 10 s)" if not rec["outage"] else "withheld windows and its own gaps"
    lines = [f"Outage protocol ({own}; {o['heads'][0]['events']} events, at the filters' defaults):", ""]
    lines += ["| row | end-of-outage error (m) | median | max | minus hold-last-fix (m) |", "|---|---|---|---|---|"]
    for h in o["heads"]:
        name = "hold last fix (measurements)" if h["filter"] == "measurements" else h["filter"]
        d = o["vs_hold"].get(h["filter"])
        dcell = "–" if d is None else f"{d[0]:+.2f} ± {_f(d[1])}" + (" (different)" if d[2] else "")
        lines.append(
            f"| {name} | {_f(h['mean_error'])} ± {_f(h['mean_error_ci95'])} | {_f(h['median_error'])} | "
            f"{_f(h['max_error'])} | {dcell} |"
        )
    if not rec["outage"]:  # the recording's own outages (dives): each one
        lines += _per_event(o)
    filt = [h for h in o["heads"] if h["filter"] != "measurements" and not h["filter"].startswith("recorded:")]
    lines += [
        "",
        "Verdict (outages, defaults): "
        + verdict(o["pairs"], filt, "mean_error", "end-of-outage difference, event by event, across events")
        + ".",
    ]
    if any(h["filter"].startswith("recorded:") for h in o["heads"]):
        lines += [
            "",
            "A `recorded:` row is the recording's own estimate, moved onto the reference by the fit its "
            "mapping declares, fitted on these same few fixes: optimistic.",
        ]
    return lines


def _tuned_section(tr) -> list:
    lines = ["", "Tuned and default, held out (last 40 %):", "", "| row | pos RMSE (m) | ± 95 % | tunes x runs |"]
    lines.append("|---|---|---|---|")
    for r in tr["rows"]:
        label = "fixes alone (measurements)" if r["kind"] == "measurements" else r["label"]
        label = label.replace("(default)", "(defaults, not tuned)") + (" — still" if r.get("still") else "")
        lines.append(f"| {label} | {_f(r['pos_rmse'], 3)} | {_f(r['ci95'], 3)} | {r['tunes']} x {r['runs']} |")
    return lines + [
        "",
        "Verdict (tuned, against the recording's reference): " + verdict(tr["pairs"], tr["rows"]) + ".",
        "",
    ]


def generate(recordings, out, work, *, filters, trials, repeats, runs, dirs, command):
    data_dir, bags_dir, root = dirs  # the Bohai folder, the bags' folder, the checkout (mappings)

    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    results = []
    for rec in recordings:
        key = rec["id"].replace("/", "_")
        cache = work / f"{key}.json"
        if cache.is_file():
            res = json.loads(cache.read_text())
            if "outages" in res and "events" not in res["outages"]:  # a cache of an earlier version: completed
                started = time.time()
                res["outages"] = outage_result(rec, filters, runs, data_dir, bags_dir, root)
                res["seconds"] = res.get("seconds", 0.0) + time.time() - started
            if "tuned" in res and any("still" not in r for r in res["tuned"]["rows"]):  # resumed: nothing computed
                res["tuned"] = tuned_result(rec, filters, trials, repeats, runs, data_dir, bags_dir, root, work / key)
            write_atomic(cache, json.dumps(res, default=float))
            results.append((rec, res))
            continue
        started = time.time()
        try:
            res = {
                "outages": outage_result(rec, filters, runs, data_dir, bags_dir, root),
                "tuned": tuned_result(rec, filters, trials, repeats, runs, data_dir, bags_dir, root, work / key),
            }
        except ReplayError as err:
            res = {"error": str(err)}
        res["seconds"] = time.time() - started
        write_atomic(cache, json.dumps(res, default=float))
        results.append((rec, json.loads(cache.read_text())))
    budget = f"filters {','.join(filters)}, {trials} trials per tune, {repeats} tunes, {runs} run(s)"
    seconds = sum(r.get("seconds", 0.0) for _, r in results)
    text = render(results, {"command": command, "budget": budget + f"; {seconds / 60:.0f} min of computation"})
    write_atomic(Path(out), text)
    return text


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m replay.reproduce.fusion_doc", description=__doc__.split("\n")[0])
    p.add_argument("--data-dir", required=True, help="the directory holding the Bohai CSV files")
    p.add_argument("--bags-dir", required=True, help="the directory holding robot_localization/test1.bag")
    p.add_argument("--out", default="docs/fusion.md")
    p.add_argument("--work", default="runs/fusion-doc", help="tunes and evaluations kept here (resumed)")
    p.add_argument("--filters", default="ekf,ukf,pf")
    p.add_argument("--trials", type=int, default=6)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--runs", type=int, default=1)
    p.add_argument("--only", default=None, help="comma-separated recording ids (default: all)")
    a = p.parse_args(argv)
    recs = [r for r in RECORDINGS if a.only is None or r["id"] in a.only.split(",")]
    command = (
        "python -m replay.reproduce.fusion_doc --data-dir BOHAI --bags-dir BAGS "
        f"--filters {a.filters} --trials {a.trials} --repeats {a.repeats} --runs {a.runs}"
    )
    root = Path(__file__).resolve().parents[2]
    generate(
        recs,
        a.out,
        a.work,
        filters=a.filters.split(","),
        trials=a.trials,
        repeats=a.repeats,
        runs=a.runs,
        dirs=(a.data_dir, a.bags_dir, root),
        command=command,
    )


if __name__ == "__main__":
    main()
