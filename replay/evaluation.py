"""``replay eval``: a campaign of one configuration per filter, computed in memory.

``evaluate`` makes one :class:`replay.pipeline.Config` per filter (parameters
validated against their declarations and stored with every default filled in)
and computes its runs with :func:`replay.pipeline.run_block` in the blocks a
campaign uses (``batch`` runs each), so ``replay eval`` and ``replay campaign
run`` give the same rows (:mod:`replay.summary`) for the same configuration.
Seeds: :mod:`replay.util.seeds` (dataset, task and filter streams per run:
every filter sees the same measurements in a run — common random numbers).

Recorded estimates of the frame (``[estimates]`` of a bag mapping) are rows
``recorded:<name>`` beside the filters, through the same pipeline and summary
(:func:`replay.pipeline.recorded_estimates`): one run each (deterministic), scored
on the task's reference; their notes (what was associated) are ``Evaluation.notes``.
"""
from __future__ import annotations

import json
import platform
import shlex
import sys
from dataclasses import dataclass, field, replace

import numpy as np

from replay import registry, scorer, summary
from replay.util.progress import particle_weight
from replay.util.version import __version__
from replay.filters import make_filter
from replay.filters.noise_params import check as check_noise, settings as noise_settings
from replay.filters.base import Estimates
from replay.pipeline import (RECORDED, RECORDED_PARAMS, Config, build_problem, config_hash, default_task, is_recorded,
                             is_sim, load_frame, plain, recorded_params, run_block)
from replay.tasks import make_task
from replay.eval_options import validate_eval_options
from replay.util.errors import ReplayError
from replay.util.lookup import params_of


DEFAULT_FILTERS = ("ekf", "ukf", "ckf", "pf")
BATCH = 25  # runs per block: the campaign default (``[campaign] batch``)


@dataclass
class FilterResult:
    name: str
    params: dict
    runs: list = field(default_factory=list)  # per-run metric dicts
    errors: list = field(default_factory=list)  # per-run error dicts
    estimates: list = field(default_factory=list)  # per-run Estimates
    summary: dict = field(default_factory=dict)  # the leaderboard row (replay.summary)
    config_hash: str = ""
    config: dict = field(default_factory=dict)  # the configuration (replay.pipeline.Config)
    records: list = field(default_factory=list)  # per-run records of replay.pipeline.run_block


@dataclass
class Evaluation:
    config: dict
    frame_meta: dict
    report: list
    results: list[FilterResult]
    t: np.ndarray
    truths: list = field(default_factory=list)  # per-run truth positions
    axis_names: tuple = ("x", "y", "z")  # names of the scored position axes
    rows: list = field(default_factory=list)  # leaderboard rows, in --filters order
    baseline: str | None = None
    notes: list = field(default_factory=list)  # one line per recorded estimate: what was associated
    units: dict = field(default_factory=dict)  # RMSE metric -> unit (replay.scorer.units)
    position_index: tuple = (0, 1, 2)  # the state components holding the scored position

    def position_components(self, name: str) -> tuple:
        """The state components of filter ``name`` holding the scored position (a recorded
        estimate's state is its position)."""
        return tuple(range(len(self.axis_names))) if is_recorded(name) else self.position_index

    def leaderboard(self):
        """The leaderboard as a DataFrame: the columns and values of ``leaderboard.csv`` (:mod:`replay.tables`)."""
        from replay import tables

        return tables.leaderboard(self)

    def estimates(self, filter: str, *, run: int | None = None):
        """A filter's estimates as a DataFrame, one row per run and step (:mod:`replay.tables`)."""
        from replay import tables

        return tables.estimates(self, filter, run=run)

    def errors(self, filter: str, *, run: int | None = None):
        """A filter's errors against the reference as a DataFrame, one row per run and step (:mod:`replay.tables`)."""
        from replay import tables

        return tables.errors(self, filter, run=run)

    def plot_errors(self, **options):
        """Position error over time, RMSE across runs per filter: a matplotlib Figure (:mod:`replay.plots`)."""
        from replay import plots

        return plots.plot_errors(self, **options)

    def first(self, n: int) -> "Evaluation":
        """This evaluation restricted to its first ``n`` runs: the numbers of an ``n``-run
        evaluation (a run's seeds and numbers depend only on (seed, run))."""
        from replay.eval_options import BY_NAME

        n = BY_NAME["runs"].check(n)
        if n >= self.config["runs"]:
            return self
        results = [FilterResult(r.name, r.params, r.runs[:n], r.errors[:n], r.estimates[:n],
                                config_hash=r.config_hash, config=r.config, records=r.records[:n])
                   for r in self.results]
        rows = _summarise(results, self.baseline)
        return replace(self, config=dict(self.config, runs=n), results=results, truths=self.truths[:n], rows=rows)


def _summarise(results: list[FilterResult], baseline: str | None) -> list[dict]:
    """Each result's leaderboard row (``summary``), labelled, with the paired columns."""
    for res in results:
        series = {r["run"]: r["series"] for r in res.records}
        res.summary = summary.config_row(res.config, res.config_hash, res.records,
                                         lambda run, cols, s=series: {k: s[run][k] for k in cols},
                                         __version__)
    rows = summary.label([r.summary for r in results])
    rows = summary.add_paired(rows, {r.config_hash: r.config for r in results},
                              {r.config_hash: r.records for r in results}, baseline)
    return summary.against_measurements(rows, {r.config_hash: r.config for r in results})


def evaluate(dataset: str, *, task: str | None = None, filters=DEFAULT_FILTERS, runs: int = 1,
             seed: int = 0, first: int | None = None, data_dir=None,
             task_params: dict | None = None, filter_params: dict | None = None,
             dataset_params: dict | None = None, adapter: str | None = None, alignment: str = "se3",
             divergence_threshold: float | None = None, baseline: str | None = None,
             batch: int = BATCH, recorded=(), progress=None,
             min_scored_share: float = summary.MIN_SCORED_SHARE.default) -> Evaluation:
    """Run ``filters`` ``runs`` times on ``dataset`` under ``task``; score every run (module docstring).

    ``filters`` may also name recorded estimates (``recorded:<name>``); ``recorded`` adds
    more by name, or, when None, every estimate the frame holds that ``filters`` does not name.
    ``min_scored_share`` (:data:`replay.summary.MIN_SCORED_SHARE`) is recorded in the configuration:
    the printed table flags rows scored on less of the reference.
    """
    min_scored_share = summary.MIN_SCORED_SHARE.check(min_scored_share)
    registry.check_data_dir(data_dir)
    opts = validate_eval_options({"task": task, "runs": runs, "seed": seed, "first": first, "data_dir": data_dir,
                                  "adapter": adapter, "task_params": task_params, "dataset_params": dataset_params,
                                  "alignment": alignment, "divergence_threshold": divergence_threshold,
                                  "baseline": baseline, "batch": batch})
    runs, seed, first, divergence_threshold, batch = (opts[k] for k in ("runs", "seed", "first",
                                                                         "divergence_threshold", "batch"))
    filters, filter_params = _check_filters(filters, filter_params, recorded)
    offline = [n for n in filters if not is_recorded(n)]
    instances = [make_filter(name, **filter_params.get(name, {})) for name in offline]  # validated up front
    if adapter is not None:
        registry.adapter_options(adapter)  # an unknown adapter: one line, even where it is not used
    dataset_params = registry.check_params(dataset, dataset_params or {}, adapter=adapter)  # canonical
    check_recorded(dataset, filters + [n if is_recorded(n) else RECORDED + n for n in recorded or ()],
                   dataset_params)
    task_name = task or default_task(dataset, first=first, data_dir=data_dir, adapter=adapter,
                                     dataset_params=dataset_params, seed=seed)
    names, estimates = _recorded(dataset, filters, recorded, seed, first, dataset_params, adapter, data_dir)
    filters = offline + names
    for name in filter_params:
        if name not in filters:
            raise ReplayError(f"parameters given for filter {name!r}, which is not among the filters run "
                              f"({', '.join(filters) or 'none'})")
    if not filters:
        raise ReplayError(f"{dataset}: nothing to score: no filter (--filters none) and no recorded estimate "
                          "(declare them in the mapping's [estimates]; docs/bags.md)")
    if baseline is not None and baseline not in filters:
        raise ReplayError(f"--baseline {baseline!r}: not among the rows ({', '.join(filters)})")
    the_task = make_task(task_name, **(task_params or {}))
    base = (dataset, plain(dataset_params or {}), first, task_name, plain(the_task.params()))
    tail = (seed, alignment, divergence_threshold, adapter)
    configs = [Config(*base, name, plain(params_of(f, "filter", name)), *tail)
               for name, f in zip(offline, instances)]
    configs += [Config(*base, name, plain(recorded_params(name[len(RECORDED):], filter_params.get(name),
                                                          estimates[name[len(RECORDED):]].params)), *tail)
                for name in names]
    built = _check_memory(configs, runs, batch, data_dir)  # run 0's problem of the first filter, reused
    if any(noise_settings(f) for f in instances):  # their sizes, known once the task is built: before any run
        built = built or {0: build_problem(configs[0], 0, data_dir)}
        for f in instances:
            check_noise(f, built[0].model)
    if offline and MEASUREMENTS not in filters:  # beside filters only: nothing to compare otherwise
        built = built or {0: build_problem(configs[0], 0, data_dir)}
        if observes_position(built[0]):  # the raw observations' row, the baseline a filter must beat
            # after the offline filters, before the recorded estimates: the order the rows take when
            # the configuration names it (a rerun passes it explicitly)
            configs.insert(len(offline), Config(*base, MEASUREMENTS, {}, *tail))
            filters = offline + [MEASUREMENTS] + names
    results = []
    if progress is not None:  # replay.util.progress.Progress: weighted by each configuration's cost
        progress.start(sum(1 if is_recorded(c.filter) else runs for c in configs),
                       sum(particle_weight(c.filter_params, 1 if is_recorded(c.filter) else runs) for c in configs))
    for cfg in configs:
        c, h = cfg.as_dict(), config_hash(cfg.as_dict())
        recs = []
        for start in range(0, 1 if is_recorded(cfg.filter) else runs, batch):
            block = list(range(start, min(runs, start + batch)))
            recs += [_filled(r) for r in run_block(c, block, data_dir, keep=True, strict=True,
                                                   built=built if cfg is configs[0] else None)]
            if progress is not None:
                progress.update(len(block), weight=particle_weight(c["filter_params"], len(block)))
        results.append(FilterResult(cfg.filter, c["filter_params"], [r["metrics"] for r in recs],
                                    [r["errors"] for r in recs], [r["estimates"] for r in recs],
                                    config_hash=h, config=c, records=recs))
    rows = _summarise(results, baseline)
    problems = [r["problem"] for r in max(results, key=lambda r: len(r.records)).records]
    p0 = problems[0]
    config = {
        "dataset": dataset, "task": task_name, "task_params": configs[0].task_params,
        "filters": filters, "filter_params": {r.name: r.params for r in results},
        "runs": runs, "seed": seed, "first": first, "dataset_params": configs[0].dataset_params,
        "adapter": adapter, "alignment": alignment, "divergence_threshold": divergence_threshold,
        "baseline": baseline, "dataset_sha256": p0.frame_meta.get("sha256"), "replay_version": __version__,
        "config_hashes": {r.name: r.config_hash for r in results},
        "min_scored_share": min_scored_share,
    }
    notes = [rec["note"] for r in results for rec in r.records if rec.get("note")]
    return Evaluation(config, plain(p0.frame_meta), p0.frame_report.to_list(), results, p0.t,
                      [p.truth_position for p in problems], tuple(p0.axis_names), rows, baseline, notes,
                      scorer.units(p0), tuple(int(i) for i in p0.position_index))


MEASUREMENTS = "measurements"  # replay.filters.measurements


def observes_position(problem) -> bool:
    """Whether every position component of the problem's state is observed directly (a fix):
    then the ``measurements`` row (the raw observations, scored alike) is added to the table."""
    from replay.filters.measurements import direct_rows

    if problem.z.shape[0] == 0:
        return False
    seen = {i for j, i, _ in direct_rows(problem.model, problem.x0)
            if np.isfinite(problem.z[:, j]).any()}
    return set(int(i) for i in problem.position_index) <= seen


def _check_filters(filters, filter_params, recorded) -> tuple[list, dict]:
    """``filters`` (names), ``filter_params`` ({name: {parameter: value}}) and ``recorded`` checked: one line."""
    if isinstance(filters, str) or not isinstance(filters, (list, tuple)) or not all(
            isinstance(f, str) and f.strip() for f in filters):
        raise ReplayError(f"filters must be a list of filter names (got {filters!r:.80})")
    if filter_params is not None and not (isinstance(filter_params, dict) and all(
            isinstance(k, str) and isinstance(v, dict) for k, v in filter_params.items())):
        raise ReplayError(f"filter_params must be an object {{filter: {{parameter: value}}}} "
                          f"(got {filter_params!r:.80})")
    if recorded is not None and (isinstance(recorded, str) or not isinstance(recorded, (list, tuple))
                                 or not all(isinstance(r, str) for r in recorded)):
        raise ReplayError(f"recorded must be a list of recorded estimate names or null (got {recorded!r:.80})")
    return list(filters), filter_params or {}


def _check_memory(configs: list, runs: int, batch: int, data_dir) -> dict | None:
    """Before any work: refuse particles or kept runs that cannot fit in memory (:mod:`replay.resources`),
    sized on run 0's problem of the first configuration, which is returned ({0: problem}: not built twice)."""
    from replay.pipeline import build_problem
    from replay.resources import available_memory, check_kept, check_particles

    offline = [c for c in configs if not is_recorded(c.filter)]
    if not offline or (avail := available_memory()) is None:
        return
    p = build_problem(offline[0], 0, data_dir)
    for c in offline:
        check_particles(c.filter, c.filter_params, min(runs, batch), p.model.nx, avail)
    check_kept(len(offline), runs, len(p.z), p.model.nx, avail)
    return {0: p} if offline[0] is configs[0] else None


def _filled(rec: dict) -> dict:
    """A run's record; a failed run (the filter failed: :mod:`replay.failures`) with NaN estimates
    and errors on the problem's steps, so every table keeps one entry per run."""
    if rec["status"] != "failed":
        return rec
    p = rec["problem"]
    n, nx = len(p.z), p.model.nx
    est = Estimates(np.full((n, nx), np.nan), np.full((n, nx, nx), np.nan), np.full(n, np.nan), None,
                    {"error": rec["error"]})
    return dict(rec, estimates=est, errors=scorer.errors(p, est), metrics={}, series={})


def failures(ev: Evaluation) -> dict:
    """``{filter: {"runs": [failed runs], "error": the first error}}`` of the filters that failed."""
    out = {}
    for res in ev.results:
        bad = [r for r in res.records if r["status"] == "failed"]
        if bad:
            out[res.name] = {"runs": [r["run"] for r in bad], "error": bad[0]["error"]}
    return out


def check_recorded(dataset, names, dataset_params) -> None:
    """Refuse, before any recording is read, a ``recorded:<name>`` of ``names`` that the mapping given
    in ``dataset_params`` does not declare in its ``[estimates]`` (without a mapping, the proposed one is
    known only from the recording: :func:`_recorded` checks after reading it)."""
    wanted = [n[len(RECORDED):] for n in names if is_recorded(n)]
    mapping = (dataset_params or {}).get("mapping")
    if not wanted or mapping is None:
        return
    from replay.adapters.bags import resolve_mapping

    declared = [e.name for e in resolve_mapping(mapping).estimates]
    unknown = [n for n in wanted if n not in declared]
    if unknown:
        raise ReplayError(f"{dataset}: no recorded estimate {unknown[0]!r} (the mapping's [estimates] "
                          f"declare: {', '.join(declared) or 'none'})")


def _recorded(dataset, filters, recorded, seed, first, dataset_params, adapter, data_dir):
    """(``recorded:<name>`` rows to compute, {name: RecordedEstimate}) from the frame's estimates."""
    named = [n for n in filters if is_recorded(n)] + [n if is_recorded(n) else RECORDED + n for n in recorded or ()]
    if not named and (recorded is not None or is_sim(dataset)):
        return [], {}
    cfg = {"dataset": dataset, "dataset_params": dataset_params, "first": first, "seed": seed, "adapter": adapter}
    estimates = getattr(load_frame(cfg, 0, data_dir), "estimates", {})
    if recorded is None:
        named += [RECORDED + k for k in estimates if RECORDED + k not in named]
    for n in named:
        if n[len(RECORDED):] not in estimates:
            raise ReplayError(f"{dataset}: no recorded estimate {n[len(RECORDED):]!r} (the mapping's [estimates] "
                              f"declare: {', '.join(estimates) or 'none'})")
    return list(dict.fromkeys(named)), estimates


def versions() -> dict:
    import scipy

    return {"replay": __version__, "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__, "platform": platform.platform()}


def command_line(config: dict) -> str:
    """The ``replay eval`` command that repeats a configuration."""
    parts = ["replay", "eval", config["dataset"], "--task", config["task"],
             "--filters", ",".join(config["filters"]), "--runs", str(config["runs"]),
             "--seed", str(config["seed"])]
    if config.get("first"):
        parts += ["--first", str(config["first"])]
    if config.get("adapter"):
        parts += ["--adapter", config["adapter"]]
    if config.get("baseline"):
        parts += ["--baseline", config["baseline"]]
    if (config.get("dataset_params") or {}).get("mapping"):
        parts += ["--mapping", str(config["dataset_params"]["mapping"])]
    try:  # name only the dataset parameters that differ from their declared defaults
        defaults = plain(registry.check_params(config["dataset"], {}, adapter=config.get("adapter")))
    except Exception:  # noqa: BLE001 — a dataset no longer registered: name them all
        defaults = {}
    for key, value in (config.get("dataset_params") or {}).items():
        if key != "mapping" and (key not in defaults or defaults[key] != value):
            text = value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
            parts += ["--dataset-param", shlex.quote(f"{key}={text}")]
    try:  # the task parameters that differ from their declared defaults
        tdefaults = plain(make_task(config["task"]).params())
    except Exception:  # noqa: BLE001 — a task no longer registered: name them all
        tdefaults = {}
    for key, value in (config.get("task_params") or {}).items():
        if key not in tdefaults or tdefaults[key] != value:
            text = value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
            parts += ["--task-param", shlex.quote(f"{key}={text}")]
    for name, params in (config.get("filter_params") or {}).items():  # those that differ from the defaults
        try:
            defaults = ({p.name: p.default for p in RECORDED_PARAMS} if is_recorded(name)
                        else plain(make_filter(name).params()))
        except Exception:  # noqa: BLE001 — a filter no longer registered: name them all
            defaults = {}
        for key, value in params.items():
            if key not in defaults or defaults[key] != value:
                text = value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
                parts += ["-p", shlex.quote(f"{name}.{key}={text}")]
    return " ".join(parts)


def manifest(ev: Evaluation) -> dict:
    return {"config": ev.config, "command": command_line(ev.config), "argv": sys.argv,
            "versions": versions(), "dataset": ev.frame_meta, "adapter_report": ev.report, "units": ev.units,
            "results": {r.name: dict(r.summary) for r in ev.results},
            **({"failures": f} if (f := failures(ev)) else {})}


