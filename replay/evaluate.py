"""``replay eval``: dataset -> frame -> task -> filters -> estimates -> scores -> outputs.

Seeds. Every random number comes from a ``numpy.random.Generator`` derived
from the user's seed ``S`` with :class:`numpy.random.SeedSequence`:

* ``(S, run, 0)``: the dataset (a simulator's truth and sensor noise);
* ``(S, run, 1)``: the task (synthesised measurement noise, the prior draw);
* ``(S, run, 2, crc32(filter name))``: the filter's own randomness.

So in a given run every filter sees the same measurements (common random
numbers: paired comparisons have tight intervals), and adding a filter changes
no other filter's numbers.

Filters whose batched form gives exactly the one-by-one numbers
(:func:`replay.filters.batched.exact`: the bootstrap PF, the particle and swarm
filters of paper 002) run all Monte Carlo runs as one array computation
(:func:`run_all`); the others run one by one. Either way the numbers are the same.
"""
from __future__ import annotations

import hashlib
import json
import platform
import shlex
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import replay
from replay import registry, score
from replay.filters import batched, make_filter
from replay.tasks import make_task
from replay.util.seeds import filter_stream, rng_for  # noqa: F401 (re-exported)

DEFAULT_FILTERS = ("ekf", "ukf", "ckf", "pf")



@dataclass
class FilterResult:
    name: str
    params: dict
    runs: list = field(default_factory=list)  # per-run metric dicts
    errors: list = field(default_factory=list)  # per-run error dicts
    estimates: list = field(default_factory=list)  # per-run Estimates
    summary: dict = field(default_factory=dict)


@dataclass
class Evaluation:
    config: dict
    frame_meta: dict
    report: list
    results: list[FilterResult]
    t: np.ndarray
    truths: list = field(default_factory=list)  # per-run truth positions
    axis_names: tuple = ("x", "y", "z")  # names of the scored position axes


def config_hash(config: dict) -> str:
    text = json.dumps({k: v for k, v in config.items() if k not in ("out",)}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def evaluate(dataset: str, *, task: str | None = None, filters=DEFAULT_FILTERS, runs: int = 1,
             seed: int = 0, first: int | None = None, data_dir=None,
             task_params: dict | None = None, filter_params: dict | None = None,
             dataset_params: dict | None = None, adapter: str | None = None) -> Evaluation:
    """Run ``filters`` ``runs`` times on ``dataset`` under ``task``; score every run."""
    ds = resolve(dataset)
    task_name = task or (ds.default_task if ds is not None else None)
    # a plain file's task: the one its adapter names in frame.meta["default_task"], else "position"
    the_task = make_task(task_name, **(task_params or {})) if task_name else None
    filter_params = filter_params or {}
    instances = [make_filter(name, **filter_params.get(name, {})) for name in filters]
    results = [FilterResult(name, f.params()) for name, f in zip(filters, instances)]
    is_sim = ds is not None and ds.kind == "sim"
    frame = None
    truths = []
    batch = [runs > 1 and batched.exact(f) for f in instances]  # filled after the loop, all runs at once
    problems = []
    for run in range(runs):
        if frame is None or is_sim:
            frame = registry.load_frame(dataset, data_dir=data_dir, rng=rng_for(seed, run, 0),
                                        first=first, adapter=adapter, **(dataset_params or {}))
        if the_task is None:
            task_name = frame.meta.get("default_task", "position")
            the_task = make_task(task_name, **(task_params or {}))
        problem = the_task.build(frame, rng_for(seed, run, 1))
        truths.append(problem.truth_position)
        if any(batch):
            problems.append(problem)
        for name, flt, res, b in zip(filters, instances, results, batch):
            if b:
                continue
            est = flt.run(problem.model, problem.z, problem.x0, problem.P0,
                          rng_for(seed, run, 2, filter_stream(name)))
            _record(res, problem, est)
    for name, flt, res, b in zip(filters, instances, results, batch):
        if b:
            for problem, est in zip(problems, run_all(flt, name, problems, seed)):
                _record(res, problem, est)
    for res in results:
        res.summary = score.aggregate(res.runs)
    config = {
        "dataset": dataset, "task": task_name, "task_params": the_task.params(),
        "filters": list(filters), "filter_params": {r.name: r.params for r in results},
        "runs": runs, "seed": seed, "first": first, "dataset_params": dataset_params or {},
        "adapter": adapter,
        "dataset_sha256": frame.meta.get("sha256"), "replay_version": replay.__version__,
    }
    config["config_hash"] = config_hash(config)
    return Evaluation(config, _jsonable(frame.meta), frame.report.to_list(), results, frame.t, truths,
                      tuple(problem.axis_names))


def _record(res: FilterResult, problem, est) -> None:
    res.runs.append(score.score_run(problem, est))
    res.errors.append(score.errors(problem, est))
    res.estimates.append(est)


BATCH_PARTICLES = 10_000  # runs per batched call: about this many particles in all


def run_all(flt, name: str, problems: list, seed: int) -> list:
    """Every run of one filter with the seeds of the one-by-one loop; batched
    (:mod:`replay.filters.batched`) when its batched form is exact and the runs
    share one model and one pattern of missing measurements. A run that
    diverges in a batch is run again alone, so the numbers are always those of
    one-by-one runs."""
    from replay.campaign.units import same_model

    def one(r):
        p = problems[r]
        return flt.run(p.model, p.z, p.x0, p.P0, rng_for(seed, r, 2, filter_stream(name)))

    p0 = problems[0]
    finite = np.isfinite(p0.z)
    if not all(p.z.shape == p0.z.shape and same_model(p.model, p0.model) and np.array_equal(np.isfinite(p.z), finite)
               for p in problems):
        return [one(r) for r in range(len(problems))]
    chunk = max(1, BATCH_PARTICLES // int(getattr(flt, "n_particles", 1)))
    out = []
    for s in range(0, len(problems), chunk):
        ps = problems[s:s + chunk]
        out += batched.run_batched(flt, p0.model, np.stack([p.z for p in ps]), np.stack([p.x0 for p in ps]),
                                   np.stack([p.P0 for p in ps]),
                                   [rng_for(seed, s + j, 2, filter_stream(name)) for j in range(len(ps))])
    return [one(r) if est.diverged else est for r, est in enumerate(out)]


def resolve(dataset: str):
    """The registry entry for a dataset id, or None for a plain file path."""
    if dataset in registry.all_datasets():
        return registry.get(dataset)
    if Path(dataset).exists() or dataset.endswith((".csv", ".bag", ".mcap", ".tsv", ".db3")):
        return None
    return registry.get(dataset)


def versions() -> dict:
    import scipy

    return {"replay": replay.__version__, "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__, "platform": platform.platform()}


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return obj


def command_line(config: dict) -> str:
    """The ``replay eval`` command that repeats a configuration."""
    parts = ["replay", "eval", config["dataset"], "--task", config["task"],
             "--filters", ",".join(config["filters"]), "--runs", str(config["runs"]),
             "--seed", str(config["seed"])]
    if config.get("first"):
        parts += ["--first", str(config["first"])]
    if config.get("adapter"):
        parts += ["--adapter", config["adapter"]]
    if (config.get("dataset_params") or {}).get("mapping"):
        parts += ["--mapping", str(config["dataset_params"]["mapping"])]
    for key, value in (config.get("dataset_params") or {}).items():
        if key != "mapping":
            text = value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
            parts += ["--dataset-param", shlex.quote(f"{key}={text}")]
    return " ".join(parts)


def manifest(ev: Evaluation) -> dict:
    return {"config": ev.config, "command": command_line(ev.config), "argv": sys.argv,
            "versions": versions(), "dataset": ev.frame_meta, "adapter_report": ev.report,
            "results": {r.name: r.summary for r in ev.results}}
