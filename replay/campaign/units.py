"""Units and jobs: what one worker computes.

A **unit** is one run of one configuration: (dataset, task, filter, parameters,
run). Its key is ``<config_hash>/<run>``, where ``config_hash`` is the hash of
the configuration's canonical JSON (:func:`config_hash`: filter and task
parameters with every default filled in, so ``{}`` and the defaults name the
same configuration). Adding a filter or a run never changes an existing key.

A **job** is a block of runs of one configuration, ``runs [b*batch, (b+1)*batch)``
less those already stored. :func:`execute_job` builds each run's problem with
the seed streams of :mod:`replay.evaluate` (``(seed, run, 0)`` data, ``(seed,
run, 1)`` task, ``(seed, run, 2, crc32(filter))`` filter), runs the filter on
the whole block at once with :mod:`replay.filters.batched` when the filter has
a batched form and the runs share one model (else one by one), and scores each
run with :func:`replay.metrics.run_metrics`. It never raises: a run that fails
comes back with ``status = "failed"`` and its error.
"""
from __future__ import annotations

import functools
import hashlib
import json
import traceback
from dataclasses import dataclass
from time import perf_counter

import numpy as np

from replay import metrics, registry
from replay.evaluate import filter_stream, resolve, rng_for
from replay.filters import make_filter
from replay.filters.batched import run_batched, supports
from replay.tasks import make_task


def config_hash(config: dict) -> str:
    text = json.dumps(config, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass
class Job:
    config: dict
    config_hash: str
    runs: list
    data_dir: str | None = None


@functools.lru_cache(maxsize=4)
def _file_frame(dataset, first, data_dir, params_json):
    """A file dataset's frame, read once per worker process (the same for every run)."""
    return registry.load_frame(dataset, data_dir=data_dir, first=first, **json.loads(params_json))


def build_problem(config: dict, run: int, data_dir=None):
    """The Problem of ``run`` under ``config``: the same streams as :func:`replay.evaluate.evaluate`."""
    ds = resolve(config["dataset"])
    seed = config["seed"]
    if ds is not None and ds.kind == "sim":
        frame = registry.load_frame(config["dataset"], data_dir=data_dir, rng=rng_for(seed, run, 0),
                                    first=config["first"], **config["dataset_params"])
    else:
        frame = _file_frame(config["dataset"], config["first"], data_dir,
                            json.dumps(config["dataset_params"], sort_keys=True))
    task = make_task(config["task"], **config["task_params"])
    return task.build(frame, rng_for(seed, run, 1))


def same_model(a, b) -> bool:
    """True when two models are the same equations (same class, equal attributes)."""
    if type(a) is not type(b):
        return False
    va, vb = vars(a), vars(b)
    if va.keys() != vb.keys():
        return False
    for k in va:
        x, y = va[k], vb[k]
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not (np.shape(x) == np.shape(y) and np.array_equal(x, y)):
                return False
        elif x is not y and x != y:
            return False
    return True


def _failed(run, err: BaseException) -> dict:
    return {"run": run, "status": "failed",
            "error": f"{type(err).__name__}: {err}".splitlines()[0][:500],
            "traceback": "".join(traceback.format_exception(err))[-4000:]}


def execute_job(job: Job) -> list[dict]:
    """Run every run of ``job``; returns one result dict per run (never raises)."""
    cfg = job.config
    results, problems = [], {}
    for run in job.runs:
        try:
            problems[run] = build_problem(cfg, run, job.data_dir)
        except Exception as err:  # recorded, the campaign goes on
            results.append(_failed(run, err))
    if not problems:
        return results
    try:
        flt = make_filter(cfg["filter"], **cfg["filter_params"])
    except Exception as err:
        return results + [_failed(run, err) for run in problems]
    runs = list(problems)
    rngs = {r: rng_for(cfg["seed"], r, 2, filter_stream(cfg["filter"])) for r in runs}
    estimates = {}
    probs = [problems[r] for r in runs]
    t0 = perf_counter()
    # batched whenever possible, even for one run: a block resumed with one run left must give the
    # numbers (and the NIS) of the whole block, whatever was stored before
    if (runs and supports(flt) and all(same_model(p.model, probs[0].model) for p in probs)
            and len({p.z.shape for p in probs}) == 1):
        try:
            out = run_batched(flt, probs[0].model, np.stack([p.z for p in probs]),
                              np.stack([p.x0 for p in probs]), np.stack([p.P0 for p in probs]),
                              [rngs[r] for r in runs])
            estimates = dict(zip(runs, out))
        except Exception:  # fall back to one by one, which says which run fails
            rngs = {r: rng_for(cfg["seed"], r, 2, filter_stream(cfg["filter"])) for r in runs}
            estimates = {}
    for r in runs:
        if r not in estimates:
            try:
                p = problems[r]
                estimates[r] = flt.run(p.model, p.z, p.x0, p.P0, rngs[r])
            except Exception as err:
                results.append(_failed(r, err))
    wall = (perf_counter() - t0) / max(len(runs), 1)
    for r in runs:
        if r not in estimates:
            continue
        try:
            results.append(_score(cfg, problems[r], estimates[r], r, wall))
        except Exception as err:
            results.append(_failed(r, err))
    return sorted(results, key=lambda d: d["run"])


def _score(cfg, problem, est, run, wall) -> dict:
    m, series = metrics.run_metrics(problem, est, cfg["alignment"], cfg["divergence_threshold"])
    from replay import score

    err = score.errors(problem, est)
    cols = {"k": np.arange(len(est.x)), "t": np.asarray(problem.t[:len(est.x)], float)}
    for i in range(est.x.shape[1]):
        cols[f"x{i}"] = est.x[:, i]
    for i in range(est.x.shape[1]):
        cols[f"P{i}{i}"] = est.P[:, i, i]
    for j, axis in enumerate(problem.axis_names):
        cols[f"ref_{axis}"] = np.where(problem.truth_valid, problem.truth_position[:, j], np.nan)
        cols[f"err_{axis}"] = err["position"][:, j]
    for name in problem.truth_angles:
        cols[f"err_{name}"] = err[name]
    cols.update(series)
    m["seconds"] = wall
    return {"run": run, "status": "done", "metrics": m, "series": cols}
