"""``replay eval``: dataset -> frame -> task -> filters -> estimates -> scores -> outputs.

Seeds. Every random number comes from a ``numpy.random.Generator`` derived
from the user's seed ``S`` with :class:`numpy.random.SeedSequence`:

* ``(S, run, 0)``: the dataset (a simulator's truth and sensor noise);
* ``(S, run, 1)``: the task (synthesised measurement noise, the prior draw);
* ``(S, run, 2, crc32(filter name))``: the filter's own randomness.

So in a given run every filter sees the same measurements (common random
numbers: paired comparisons have tight intervals), and adding a filter changes
no other filter's numbers.
"""
from __future__ import annotations

import hashlib
import json
import platform
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import replay
from replay import registry, score
from replay.filters import make_filter
from replay.tasks import make_task

DEFAULT_FILTERS = ("ekf", "ukf", "ckf", "pf")


def rng_for(seed: int, run: int, *stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(run), *stream]))


def filter_stream(name: str) -> int:
    return zlib.crc32(name.encode())


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
    for run in range(runs):
        if frame is None or is_sim:
            frame = registry.load_frame(dataset, data_dir=data_dir, rng=rng_for(seed, run, 0),
                                        first=first, adapter=adapter, **(dataset_params or {}))
        if the_task is None:
            task_name = frame.meta.get("default_task", "position")
            the_task = make_task(task_name, **(task_params or {}))
        problem = the_task.build(frame, rng_for(seed, run, 1))
        truths.append(problem.truth_position)
        for name, flt, res in zip(filters, instances, results):
            est = flt.run(problem.model, problem.z, problem.x0, problem.P0,
                          rng_for(seed, run, 2, filter_stream(name)))
            res.runs.append(score.score_run(problem, est))
            res.errors.append(score.errors(problem, est))
            res.estimates.append(est)
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
    return " ".join(parts)


def manifest(ev: Evaluation) -> dict:
    return {"config": ev.config, "command": command_line(ev.config), "argv": sys.argv,
            "versions": versions(), "dataset": ev.frame_meta, "adapter_report": ev.report,
            "results": {r.name: r.summary for r in ev.results}}
