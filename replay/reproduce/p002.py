"""``replay reproduce 002``: the IGWO-STCPF paper's claims beside ours, with baselines and ablations.

Three parts, each a list of :func:`replay.run.evaluation.evaluate` calls (the pipeline
of ``replay eval``; every table prints the ``replay eval`` commands that give
its rows) rendered into sections and verdict claims:

* ``tables`` (:mod:`.p002_sim`, :mod:`.p002_checks`): UNGM (benchmark 1),
  Tables 5 and 6 with the PSO filters bounded and unbounded and the baselines,
  the PSO box, Fig. 9, the R and N sweeps, STCKF as printed, the position-error
  definition, the IGWO entropy weights, the geometry of the sonar benchmark;
* ``ablations`` (:mod:`.p002_ablations`): the swarm ablations, the STCPF
  proposal (ESS), the printed a(t), reproducibility (``RERUN_RTOL``);
* ``bohai`` (:mod:`.p002_bohai`): benchmark 3 with 20 runs per sequence and the
  measurement-only fit of the optimiser.

``part=None`` runs all three. A part's output (Markdown, claims, command, time)
is kept in ``<doc stem>_parts.json`` beside the document, and the document is
assembled from every part kept there, so ``--part bohai`` refreshes only the
Bohai sections and the verdict table keeps the other parts' claims.
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path

from replay.reproduce.verdict import Claim, Stopwatch, check_portable, footer, verdict_table, write_document
from replay.util.errors import ReplayError
from replay.util.files import write_atomic

from . import p002_ablations, p002_bohai, p002_checks, p002_sim
from .p002_common import Settings, run_jobs
from .pool import pool, workers

PARTS = ("tables", "ablations", "bohai")
DOC = Path("docs/reproduction/002.md")  # relative to the working directory, as 000, 001, 003


def path_for(doc) -> Path:
    return Path(doc) if doc else DOC


def first_runs(ev, n: int):
    """The evaluation restricted to its first ``n`` runs (:meth:`replay.run.evaluation.Evaluation.first`)."""
    return ev.first(n)


def compute(part: str, s: Settings, executor=None) -> tuple[list[str], list[Claim]]:
    """Run the jobs of ``part`` (in ``executor``'s worker processes, or here when None) and render
    it: (Markdown lines, claims)."""
    if part == "tables":
        evs = run_jobs(p002_sim.jobs(s) + p002_checks.jobs(s), s, part, executor)
        lines, claims, ctx = p002_sim.render(evs, s)
        more, claims2 = p002_checks.render(evs, s, ctx)
        return lines + more, claims + claims2
    if part == "ablations":
        return p002_ablations.render(run_jobs(p002_ablations.jobs(s), s, part, executor), s)
    if part == "bohai":
        return p002_bohai.render(run_jobs(p002_bohai.jobs(s), s, part, executor), s)
    raise ReplayError(f"reproduce 002: unknown part {part!r} (one of {', '.join(PARTS)})")


def command(part, runs, seed, data_dir, quick) -> str:
    return ("replay reproduce 002" + (f" --part {part}" if part else "") + (f" --runs {runs}" if runs else "")
            + (" --quick" if quick else "") + f" --seed {seed}"
            + (f" --data-dir {os.path.relpath(data_dir)}" if data_dir else ""))


def load_parts(path: Path) -> dict:
    try:
        return json.loads(path.read_text(encoding="utf-8"))["parts"]
    except (OSError, ValueError, KeyError):
        return {}


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False, part=None):
    """Compute ``part`` (None or ``all``: every part) and write the document (module docstring)."""
    doc = path_for(doc)
    todo = PARTS if part in (None, "all") else (part,)
    for p in todo:
        if p not in PARTS:
            raise ReplayError(f"reproduce 002: unknown part {p!r} (one of {', '.join(PARTS)}, all)")
    s = Settings(runs, seed, data_dir, quick, quiet, doc)
    doc.parent.mkdir(parents=True, exist_ok=True)
    store_path = doc.with_name(f"{doc.stem}_parts.json")
    store = load_parts(store_path) if part not in (None, "all") else {}
    watch = Stopwatch()
    n = workers()
    with pool(n) as ex:  # one pool for every part: the workers start once
        for p in todo:
            w = Stopwatch()
            lines, claims = compute(p, s, ex)
            store[p] = {"markdown": "\n".join(lines), "claims": [asdict(c) for c in claims],
                        "command": command(p, runs, seed, data_dir, quick), "seconds": round(w.seconds, 1),
                        "workers": n}
            if not quiet:
                print(f"part {p}: {w.seconds:.0f} s ({n} worker processes)", flush=True)
    text = json.dumps({"parts": store}, indent=1, ensure_ascii=False)
    check_portable(text, str(store_path))
    doc.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(store_path, text + "\n")
    write_document(doc, assemble(store, command(None if part in (None, "all") else part, runs, seed, data_dir,
                                                quick), watch.seconds))
    if not quiet:
        print(f"wrote {doc} ({watch.seconds:.0f} s)")
    return doc


def assemble(store: dict, cmd: str, seconds: float) -> str:
    claims = [Claim(**c) for p in PARTS if p in store for c in store[p]["claims"]]
    missing = [p for p in PARTS if p not in store]
    out = ["# Reproduction of paper 002 (IGWO-STCPF)", "",
           "Every claim of the paper with our number (mean over Monte Carlo runs ± half-width of the 95 % "
           "Student-t interval), the paper's, and the verdict; the evidence sections follow, each table with the "
           "`replay eval` commands that give its rows. All filters of a table run on the same noise in each run "
           "(seeds (seed, run, stream), `replay/run/evaluation.py`): paired Δ columns have tight intervals.", "",
           "## Verdicts", "", verdict_table(claims), ""]
    if missing:
        out += [f"Parts not run yet: {', '.join(missing)} (`replay reproduce 002 --part NAME`).", ""]
    for p in PARTS:
        if p in store:
            out += [store[p]["markdown"], ""]
    out += ["## Parts and timing", "",
            "`replay reproduce 002` runs every part; `--part tables|ablations|bohai` runs one and keeps the others' "
            "sections (from `002_parts.json` beside this file). Wall time on the project's 2-core machine, the "
            "evaluations of a part computed in `REPLAY_WORKERS` worker processes (default 2), the costliest first "
            "(each evaluation draws from its own seeded streams: the numbers do not depend on the workers):", "",
            "| part | command | worker processes | seconds |", "|---|---|---|---|"]
    out += [f"| {p} | `{store[p]['command']}` | {store[p].get('workers', 1)} | {store[p]['seconds']:.0f} |"
            for p in PARTS if p in store]
    out += [f"| all | | | {sum(store[p]['seconds'] for p in PARTS if p in store):.0f} |", ""] + NOTES.splitlines()
    return "\n".join(out) + "\n" + footer(cmd, seconds)


NOTES = """## Choices and notes

* The models and algorithms follow the paper where it is explicit; every ambiguity is decided in the docstring
  of the module that implements it, with a parameter for the other reading: `filters/p002/stckf.py` (M of the
  fading factor, scaling of the prior, covariance repair), `filters/p002/stcpf.py` (the per-particle prior:
  `prior_cov`), `filters/p002/gwo.py` (a(t): `a_form`; the leader candidates), `filters/p002/igwo_stcpf.py`
  (fitness, moved components, where the estimate is taken), `filters/p002/pso.py` (bounds),
  `replay/models/ungm.py`, `replay/sim/auv_sonar.py` (geometry: `truth_noise`, `x0`, `steps`). Nothing was
  tuned toward the paper's numbers; the defaults are the readings of the paper, the ablations the alternatives.
* Our sonar errors are larger than the paper's for every filter; the geometry section shows that the
  paper's X / Y level is reached when the trajectory stays inside the paper's own PSO box.
* The swarm filters are chaotic at rounding level; `replay rerun` checks them to their `RERUN_RTOL`
  (reproducibility section). Speed: `benchmarks/bench_002.py` times one run and a batch against Table 4."""
