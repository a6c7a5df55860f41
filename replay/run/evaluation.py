"""``replay eval``: a campaign of one configuration per filter, computed in memory.

``evaluate`` makes one :class:`replay.run.pipeline.Config` per filter (parameters
validated against their declarations and stored with every default filled in)
and computes its runs with :func:`replay.run.pipeline.run_block` in the blocks a
campaign uses (``batch`` runs each), so ``replay eval`` and ``replay campaign
run`` give the same rows (:mod:`replay.scoring.summary`) for the same configuration.
Seeds: :mod:`replay.util.seeds` (dataset, task and filter streams per run:
every filter sees the same measurements in a run — common random numbers).

Recorded estimates of the frame (``[estimates]`` of a bag mapping) are rows
``recorded:<name>`` beside the filters, through the same pipeline and summary
(:func:`replay.trajectory.recorded.recorded_estimates`): one run each (deterministic), scored
on the task's reference; their notes (what was associated) are ``Evaluation.notes``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from replay.data import dataset_ref, registry
from replay.scoring import gap, scorer, summary
from replay.scoring.record import FAILED, RunRecord
from replay.util.progress import particle_weight
from replay.util.version import __version__
from replay.filters import make_filter
from replay.filters.noise_params import check as check_noise, settings as noise_settings
from replay.filters.base import Estimates
from replay.filters.gating import per_filter
from replay.run.pipeline import Config, build_problem, config_hash, default_task, plain, run_block
from replay.trajectory.recorded import RECORDED, is_recorded, recorded_params
from replay.tasks import make_task
from replay.run.eval_options import BY_NAME, DEFAULTS, EvalOptions
from replay.util.errors import ReplayError
from replay.util.lookup import params_of
from replay.run.checks import check_filters, check_memory, check_recorded, recorded_rows
from replay.run import plots, tables
from replay.filters.measurements import direct_rows


BATCH = DEFAULTS["batch"]  # runs per block: the campaign default (``[campaign] batch``)


@dataclass
class FilterResult:
    name: str
    params: dict
    runs: list = field(default_factory=list)  # per-run metric dicts
    errors: list = field(default_factory=list)  # per-run error dicts
    estimates: list = field(default_factory=list)  # per-run Estimates
    summary: dict = field(default_factory=dict)  # the leaderboard row (replay.scoring.summary)
    config_hash: str = ""
    config: dict = field(default_factory=dict)  # the configuration (replay.run.pipeline.Config)
    records: list[RunRecord] = field(default_factory=list)  # per-run records of replay.run.pipeline.run_block


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
    units: dict = field(default_factory=dict)  # RMSE metric -> unit (replay.scoring.scorer.units)
    position_index: tuple = (0, 1, 2)  # the state components holding the scored position

    def position_components(self, name: str) -> tuple:
        """The state components of filter ``name`` holding the scored position (a recorded
        estimate's state is its position)."""
        return tuple(range(len(self.axis_names))) if is_recorded(name) else self.position_index

    def leaderboard(self):
        """The leaderboard as a DataFrame: the columns and values of ``leaderboard.csv`` (:mod:`replay.run.tables`)."""
        return tables.leaderboard(self)

    def estimates(self, filter: str, *, run: int | None = None):
        """A filter's estimates as a DataFrame, one row per run and step (:mod:`replay.run.tables`)."""
        return tables.estimates(self, filter, run=run)

    def errors(self, filter: str, *, run: int | None = None):
        """A filter's errors against the reference as a DataFrame, one row per run and step
        (:mod:`replay.run.tables`)."""
        return tables.errors(self, filter, run=run)

    def plot_errors(self, **options):
        """Position error over time, RMSE across runs per filter: a matplotlib Figure (:mod:`replay.run.plots`)."""
        return plots.plot_errors(self, **options)

    def first(self, n: int) -> "Evaluation":
        """This evaluation restricted to its first ``n`` runs: the numbers of an ``n``-run
        evaluation (a run's seeds and numbers depend only on (seed, run))."""
        n = BY_NAME["runs"].check(n)
        if n >= self.config["runs"]:
            return self
        results = [
            FilterResult(
                r.name,
                r.params,
                r.runs[:n],
                r.errors[:n],
                r.estimates[:n],
                config_hash=r.config_hash,
                config=r.config,
                records=r.records[:n],
            )
            for r in self.results
        ]
        rows = _summarise(results, self.baseline)
        return replace(self, config=dict(self.config, runs=n), results=results, truths=self.truths[:n], rows=rows)


def _summarise(results: list[FilterResult], baseline: str | None) -> list[dict]:
    """Each result's leaderboard row (``summary``), labelled, with the paired columns."""
    for res in results:
        series = {r.run: r.series for r in res.records}
        res.summary = summary.config_row(
            res.config,
            res.config_hash,
            res.records,
            lambda run, cols, s=series: {k: s[run][k] for k in cols},
            __version__,
        )
    rows = summary.label([r.summary for r in results])
    configs, records = {r.config_hash: r.config for r in results}, {r.config_hash: r.records for r in results}
    rows = gap.add_gap(summary.add_paired(rows, configs, records, baseline), configs, records)
    return summary.against_measurements(rows, configs, records)


def evaluate(dataset, options: EvalOptions | None = None, *, progress=None) -> Evaluation:
    """Run ``options.filters`` ``options.runs`` times on ``dataset`` under ``options.task``; score every run
    (module docstring). ``options``: an :class:`EvalOptions` (checked when made; None: the defaults).

    ``filters`` may also name recorded estimates (``recorded:<name>``); ``recorded`` adds
    more by name, or, when None, every estimate the frame holds that ``filters`` does not name.
    ``min_scored_share`` (:data:`replay.scoring.summary.MIN_SCORED_SHARE`) is recorded in the configuration:
    the printed table flags rows scored on less of the reference. ``progress``: a
    :class:`replay.util.progress.Progress` told of each block of runs done.
    """
    o = EvalOptions() if options is None else options
    registry.check_data_dir(o.data_dir)
    s = _resolve(dataset, o)
    configs, built = _configs(s, o.task_params)
    _start_progress(progress, configs, o.runs)
    results = [_run_config(cfg, s, built if cfg is configs[0] else None, progress) for cfg in configs]
    return _assemble(s, configs, results, o.min_scored_share)


@dataclass
class Resolved:
    """An evaluation's settings once resolved (:func:`_resolve`): its ``options`` (checked when made),
    the dataset id parsed and its parameters made canonical, the task named, the filters made, the
    recorded rows found. ``filters``: every row in order (it gains ``measurements`` where it applies)."""

    options: EvalOptions
    dataset: str  # the id, as the configurations and the manifest record it
    dataset_params: dict  # canonical (every default filled in)
    task_name: str
    filter_params: dict  # {row: {parameter: value}} as given
    offline: list  # the filters run (names)
    instances: list  # the filters made (their parameters validated up front)
    names: list  # the recorded rows (recorded:<name>)
    estimates: dict  # the frame's recorded estimates, by name
    filters: list  # every row, in order


def _resolve(dataset, o: EvalOptions) -> Resolved:
    """The resolved settings of an evaluation (the options checked when ``o`` was made; the filters made,
    the dataset id parsed, the task named, the recorded rows found), in the order ``evaluate`` checks them."""
    filters, filter_params = check_filters(o.filters, o.filter_params, o.recorded)
    offline = [n for n in filters if not is_recorded(n)]
    instances = [make_filter(name, **filter_params.get(name, {})) for name in offline]  # validated up front
    adapter, data_dir, first, seed, recorded = o.adapter, o.data_dir, o.first, o.seed, o.recorded
    if adapter is not None:
        registry.adapter_options(adapter)  # an unknown adapter: one line, even where it is not used
    ref = dataset_ref.resolve(dataset, adapter)  # the id parsed once, here (or a DatasetRef handed in)
    dparams = registry.check_params(ref.target, o.dataset_params or {}, adapter=adapter)  # canonical
    check_recorded(ref.id, filters + [n if is_recorded(n) else RECORDED + n for n in recorded or ()], dparams)
    task = o.task or default_task(
        ref, first=first, data_dir=data_dir, adapter=adapter, dataset_params=dparams, seed=seed
    )
    names, estimates = recorded_rows(ref, filters, recorded, seed, first, dparams, adapter, data_dir)
    s = Resolved(o, ref.id, dparams, task, filter_params, offline, instances, names, estimates, offline + names)
    _check_rows(s.dataset, s.filters, s.filter_params, o.baseline)
    return s


def _check_rows(dataset: str, filters: list, filter_params: dict, baseline: str | None) -> None:
    """Every parameter set and the baseline name a row that runs, and some row runs."""
    for name in filter_params:
        if name not in filters:
            raise ReplayError(
                f"parameters given for filter {name!r}, which is not among the filters run "
                f"({', '.join(filters) or 'none'})"
            )
    if not filters:
        raise ReplayError(
            f"{dataset}: nothing to score: no filter (--filters none) and no recorded estimate "
            "(declare them in the mapping's [estimates]; docs/bags.md)"
        )
    if baseline is not None and baseline not in filters:
        raise ReplayError(f"--baseline {baseline!r}: not among the rows ({', '.join(filters)})")


def _configs(s: Resolved, task_params: dict | None) -> tuple[list[Config], dict | None]:
    """One configuration per row (offline filters, ``measurements`` where it applies, recorded
    estimates) and the problems built while checking them (``built``: run 0's of the first);
    ``s.filters`` gains ``measurements`` when its row is added."""
    the_task = make_task(s.task_name, **(task_params or {}))
    o = s.options
    base = (s.dataset, plain(s.dataset_params or {}), o.first, s.task_name, plain(the_task.params()))
    tail = (o.seed, o.alignment, o.divergence_threshold, o.adapter)
    configs = [
        Config(*base, name, plain(params_of(f, "filter", name)), *tail) for name, f in zip(s.offline, s.instances)
    ]
    configs += [Config(*base, name, plain(_recorded_params(s, name)), *tail) for name in s.names]
    built = check_memory(configs, o.runs, o.batch, o.data_dir)  # run 0's problem of the first filter, reused
    if any(noise_settings(f) for f in s.instances):  # their sizes, known once the task is built: before any run
        built = built or {0: build_problem(configs[0], 0, o.data_dir)}
        for f in s.instances:
            check_noise(f, built[0].model)
    if s.offline and MEASUREMENTS not in s.filters:  # beside filters only: nothing to compare otherwise
        built = built or {0: build_problem(configs[0], 0, o.data_dir)}
        if observes_position(built[0]):  # the raw observations' row, the baseline a filter must beat
            # after the offline filters, before the recorded estimates: the order the rows take when
            # the configuration names it (a rerun passes it explicitly)
            configs.insert(len(s.offline), Config(*base, MEASUREMENTS, {}, *tail))
            s.filters = s.offline + [MEASUREMENTS] + s.names
    return configs, built


def _recorded_params(s: Resolved, name: str) -> dict:
    """The parameters of recorded row ``name`` (``recorded:<estimate>``)."""
    estimate = name[len(RECORDED) :]
    return recorded_params(estimate, s.filter_params.get(name), s.estimates[estimate].params)


def _start_progress(progress, configs: list[Config], runs: int) -> None:
    """Start ``progress`` (:class:`replay.util.progress.Progress`), weighted by each configuration's cost."""
    if progress is not None:
        progress.start(
            sum(1 if is_recorded(c.filter) else runs for c in configs),
            sum(particle_weight(c.filter_params, 1 if is_recorded(c.filter) else runs) for c in configs),
        )


def _run_config(cfg: Config, s: Resolved, built: dict | None, progress) -> FilterResult:
    """The runs of one configuration, in blocks of ``options.batch`` (a recorded estimate: one run)."""
    runs, batch = s.options.runs, s.options.batch
    c, h = cfg.as_dict(), config_hash(cfg.as_dict())
    recs = []
    n = 1 if is_recorded(cfg.filter) else runs  # a recorded estimate: run 0 only (20/11 runs counted before)
    for start in range(0, n, batch):
        block = list(range(start, min(n, start + batch)))
        recs += [_filled(r) for r in run_block(c, block, s.options.data_dir, keep=True, strict=True, built=built)]
        if progress is not None:
            progress.update(len(block), weight=particle_weight(c["filter_params"], len(block)))
    return FilterResult(
        cfg.filter,
        c["filter_params"],
        [r.metrics for r in recs],
        [r.errors for r in recs],
        [r.estimates for r in recs],
        config_hash=h,
        config=c,
        records=recs,
    )


def _assemble(s: Resolved, configs: list[Config], results: list[FilterResult], min_scored_share) -> Evaluation:
    """The Evaluation: the rows, the configuration as a campaign records it, the frame's meta and report,
    the truths of the runs and the recorded estimates' notes."""
    o = s.options
    rows = _summarise(results, o.baseline)
    problems = [r.problem for r in max(results, key=lambda r: len(r.records)).records]
    p0 = problems[0]
    config = {
        "dataset": s.dataset,
        "task": s.task_name,
        "task_params": configs[0].task_params,
        "filters": s.filters,
        "filter_params": {r.name: r.params for r in results},
        "runs": o.runs,
        "seed": o.seed,
        "first": o.first,
        "dataset_params": configs[0].dataset_params,
        "adapter": o.adapter,
        "alignment": o.alignment,
        "divergence_threshold": o.divergence_threshold,
        "baseline": o.baseline,
        "dataset_sha256": p0.frame_meta.get("sha256"),
        "replay_version": __version__,
        "config_hashes": {r.name: r.config_hash for r in results},
        "min_scored_share": min_scored_share,
    }
    notes = [rec.note for r in results for rec in r.records if rec.note]
    notes += [
        f"{name}: gating rejected (per run) " + "; ".join(f"{k} {v}" for k, v in counts.items())
        for name, counts in per_filter(results).items()
    ]
    return Evaluation(
        config,
        plain(p0.frame_meta),
        p0.frame_report.to_list(),
        results,
        p0.t,
        [p.truth_position for p in problems],
        tuple(p0.axis_names),
        rows,
        o.baseline,
        notes,
        scorer.units(p0),
        tuple(int(i) for i in p0.position_index),
    )


MEASUREMENTS = "measurements"  # replay.filters.measurements


def observes_position(problem) -> bool:
    """Whether every position component of the problem's state is observed directly (a fix):
    then the ``measurements`` row (the raw observations, scored alike) is added to the table."""
    if problem.z.shape[0] == 0:
        return False
    seen = {i for j, i, _ in direct_rows(problem.model, problem.x0) if np.isfinite(problem.z[:, j]).any()}
    return set(int(i) for i in problem.position_index) <= seen


def _filled(rec: RunRecord) -> RunRecord:
    """A run's record; a failed run (the filter failed: :mod:`replay.run.failures`) with NaN estimates
    and errors on the problem's steps, so every table keeps one entry per run."""
    if rec.status != FAILED:
        return rec
    p = rec.problem
    n, nx = len(p.z), p.model.nx
    est = Estimates(
        np.full((n, nx), np.nan), np.full((n, nx, nx), np.nan), np.full(n, np.nan), None, {"error": rec.error}
    )
    return replace(rec, estimates=est, errors=scorer.errors(p, est), metrics={}, series={})
