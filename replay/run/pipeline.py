"""The one evaluation pipeline: a configuration and a block of runs -> one scored record per run.

Everything that prints or stores a number goes through here: ``replay eval`` (:func:`replay.run.evaluation.evaluate`,
an in-memory campaign with one configuration per filter), ``replay campaign run`` (a job is a block of runs
of one configuration, :func:`replay.campaign.units.execute_job`), ``replay reproduce`` and ``replay rerun``.

A :class:`Config` is one dataset x task x filter x parameters x seed; its
hash (:func:`config_hash`) names it everywhere (leaderboards, campaign
directories, manifests). Parameters are stored canonically, every default
filled in, so ``{}`` and the defaults are the same configuration.

:func:`run_block` computes runs ``runs`` of a configuration:

1. each run's problem (:func:`build_problem`): the frame (a simulator draws it
   from the run's data stream; a file is read once), then the task builds the
   measurements and prior from the task stream (seed streams: :mod:`replay.util.seeds`);
2. the filter runs every run of the block in one call of :meth:`replay.filters.base.Filter.run_batch`
   (runs sharing one model and one pattern of missing measurements; otherwise in groups that do), on the
   model and priors under its own noise settings (:mod:`replay.filters.noise_params`). Every filter is
   written over the Monte Carlo run axis and each run draws only from its own generator, so a run's
   numbers do not depend on which runs share its block: eval and campaign agree by construction;
3. each run is scored by :func:`replay.scoring.metrics.run_metrics` (RMSE per axis and
   angle, ATE, drift, NEES/NIS) into a :class:`replay.scoring.record.RunRecord` (run, status,
   metrics, series); ``keep=True`` also keeps the problem, the estimates and the
   error series in memory (``replay eval`` writes and plots them).

It never raises for one run: a run whose problem cannot be built or whose
scoring fails comes back as ``status = "failed"`` with its error.

**Recorded estimates** (``Frame.estimates``: an onboard EKF's odometry, a SLAM
system's poses) are configurations too: ``filter = "recorded:<name>"`` with the
association parameters as its parameters (:mod:`replay.trajectory.recorded`). Nothing is
filtered: :func:`replay.trajectory.recorded.recorded_estimates` associates the recorded poses with
the task's reference and the run is scored by the same
:func:`score_record`. A recorded estimate is deterministic: it has one run, run 0
(:func:`runs_of`), whatever the number of runs asked for.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter

import numpy as np

from replay import roles
from replay.data import dataset_ref, fault_apply, registry, views
from replay.filters import make_filter
from replay.filters.base import check_batch
from replay.filters.noise_params import apply as apply_noise
from replay.util.canonical import config_hash, plain  # noqa: F401 (the pipeline's names too)
from replay.run.eval_options import DEFAULTS
from replay.run.failures import ends_run, failed
from replay.scoring import likelihood, marks, metrics, provenance, scorer
from replay.scoring.record import DONE, RunRecord
from replay.tasks import make_task, reference_coverage, reference_present, source_of
from replay.trajectory.recorded import RECORDED, is_recorded, recorded_estimates, unaligned_metrics
from replay.util import covcols
from replay.util.errors import ReplayError, shown
from replay.util.seeds import DATA, FAULT, TASK, filter_rng, rng_for


@dataclass(frozen=True)
class Config:
    """One configuration: everything that fixes the numbers of its runs except the run index."""

    dataset: str
    dataset_params: dict
    first: int | None
    task: str
    task_params: dict
    filter: str
    filter_params: dict
    seed: int
    alignment: str = DEFAULTS["alignment"]
    divergence_threshold: float | None = None
    adapter: str | None = None

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def resolve(dataset):
    """The registry entry for a dataset id, or None for a plain file path (:mod:`replay.data.dataset_ref`)."""
    return dataset_ref.resolve(dataset).entry


def is_sim(dataset) -> bool:
    return dataset_ref.resolve(dataset).is_sim


@functools.lru_cache(maxsize=2)
def _file_read(dataset, data_dir, adapter, params_json, state=()):
    """A file dataset's frame as its adapter reads it (no view, no ``first``), read once per process
    while the file is unchanged: ``state`` (:func:`_file_state`) is part of the key, so an edited file
    is read again. A tune's training and test segments and its whole-recording rows are cut from
    this one read (the bag was decoded once per view before)."""
    return registry.load_frame(dataset, data_dir=data_dir, adapter=adapter, **json.loads(params_json))


@functools.lru_cache(maxsize=4)
def _file_frame(dataset, first, data_dir, adapter, params_json, state=()):
    """A file dataset's frame with its views and ``first`` (the same for every run): cut from the
    one read of :func:`_file_read` (checked first: a bad view is refused before the file is read)."""
    chosen, own = views.split(json.loads(params_json))
    chosen, first = views.check(chosen, f"dataset {shown(dataset)}"), registry.FIRST.check(first)
    frame = _file_read(dataset, data_dir, adapter, json.dumps(own, sort_keys=True), state)
    return registry.cut(frame, chosen, first, str(dataset)) if chosen or first is not None else frame


def forget_frames() -> None:
    """Forget the files' frames read by this process (the next run reads its file again)."""
    _file_read.cache_clear()
    _file_frame.cache_clear()


def _file_state(target, data_dir) -> tuple:
    """(path, size, mtime, inode) of the file a file dataset reads (of each file of a bag
    directory); () when it is not found (the registry then refuses in its own words)."""
    try:
        path = registry.locate(target, data_dir) if isinstance(target, registry.Dataset) else Path(target).expanduser()
        files = [] if path is None else sorted(path.iterdir()) if path.is_dir() else [path]
        return tuple((str(f), st.st_size, st.st_mtime_ns, st.st_ino) for f in files for st in [f.stat()])
    except (OSError, ReplayError):
        return ()


def load_frame(config: Config | dict, run: int, data_dir=None, ds=False):
    """The frame of ``run``: drawn from the run's data stream for a simulator, read once for a file
    (``ds``: the dataset's registry entry, :func:`resolve`, when the caller has it already)."""
    c = config.as_dict() if isinstance(config, Config) else config
    injected = c["dataset_params"].get("fault")
    if injected:  # the clean frame (a file's read once), then the run's own fault draw (replay.data.faults)
        clean = load_frame(
            dict(c, dataset_params={k: v for k, v in c["dataset_params"].items() if k != "fault"}), run, data_dir, ds
        )
        return fault_apply.apply(clean, injected, rng_for(c["seed"], run, FAULT), str(c["dataset"]))
    ds = resolve(c["dataset"]) if ds is False else ds
    if ds is not None and ds.kind == "sim":  # the entry itself: the registry looks it up no more
        return registry.load_frame(
            ds,
            data_dir=data_dir,
            rng=rng_for(c["seed"], run, DATA),
            first=c["first"],
            adapter=c.get("adapter"),
            **c["dataset_params"],
        )
    data_dir = None if data_dir is None else str(data_dir)
    return _file_frame(
        c["dataset"],
        c["first"],
        data_dir,
        c.get("adapter"),
        json.dumps(c["dataset_params"], sort_keys=True),
        _file_state(c["dataset"] if ds is None else ds, data_dir)
        + (_file_state(c["dataset_params"]["mapping"], None) if c["dataset_params"].get("mapping") else ()),
    )  # the mapping file's state too: an edited mapping is read again


def default_task(dataset, *, first=None, data_dir=None, adapter=None, dataset_params=None, seed=0) -> str:
    """The task when none is named: the registry's, the adapter's, else ``fusion`` for a recording
    with sensor inputs (``Frame.roles``), ``position`` (rows marked ``synthetic``) without.
    ``dataset``: an id or a :class:`replay.data.dataset_ref.DatasetRef`."""
    ref = dataset_ref.resolve(dataset)
    if ref.entry is not None and ref.entry.default_task:
        return ref.entry.default_task
    cfg = {"dataset": ref.id, "dataset_params": dataset_params or {}, "first": first, "seed": seed, "adapter": adapter}
    frame = load_frame(cfg, 0, data_dir, ds=ref.entry)
    sensors = any(i.role != roles.NONE for i in frame.roles or ())
    return frame.default_task or ("fusion" if sensors else "position")


def build_problem(config: Config | dict, run: int, data_dir=None, ds=False):
    """The Problem of ``run`` under ``config`` (frame, then the task on the run's task stream)."""
    c = config.as_dict() if isinstance(config, Config) else config
    frame = load_frame(c, run, data_dir, ds)
    task = make_task(c["task"], **c["task_params"])
    problem = task.judge(task.build(frame, rng_for(c["seed"], run, TASK)))
    own = getattr(problem, "reference_extent", None)  # a task's own reference (fusion score=outages): its extent
    problem.truth_present = reference_present(frame, len(problem.truth_valid)) if own is None else own
    problem.truth_missing, note = reference_coverage(problem.t, problem.truth_present) if own is None else (0, None)
    problem.notes = list(problem.notes) + ([note] if note else [])
    # the manifest's "dataset" section: the frame's metadata plus what the task used and noted
    problem.frame_meta = dict(
        frame.meta, task_inputs=getattr(problem, "inputs", {}), task_notes=getattr(problem, "notes", [])
    )
    if frame.roles is not None:  # the adapter's sensor inputs (Frame.roles), as the manifest records them
        problem.frame_meta.update(roles=roles.as_meta(frame.roles))
    problem.frame_meta.update(frame.records())  # the simulation, maneuvers, columns, default task
    if getattr(problem, "noise", None):  # the fusion task: where each input's noise came from
        problem.frame_meta["task_noise"] = problem.noise
    problem.frame_meta["reference"] = provenance.provenance(  # issue 35: printed on every table
        frame.meta,
        problem.frame_meta["task_inputs"],
        {**c["task_params"], **(problem.params or {})},
        simulated=dataset_ref.simulated(c["dataset"]),
        synthetic=bool(getattr(task, "SYNTHETIC", False)),
        declared=getattr(problem, "reference_provenance", None),  # a task scoring against its own reference
        unconstrained=getattr(problem, "unconstrained", ()),  # an angle nothing measures (fusion_heading.py)
    )
    problem.frame_report = frame.report
    problem.recorded = frame.estimates  # for the scorer of recorded:<name> configurations only
    problem.source = source_of(frame)
    return problem


def _groups(runs, problems):
    """Runs that can share one batched call: same model equations, same measurement shape and
    the same pattern of missing measurements."""
    groups: list[list[int]] = []
    for r in runs:
        p = problems[r]
        for g in groups:
            q = problems[g[0]]
            if (
                p.z.shape == q.z.shape
                and same_model(p.model, q.model)
                and np.array_equal(np.isfinite(p.z), np.isfinite(q.z))
            ):
                g.append(r)
                break
        else:
            groups.append([r])
    return groups


def same_model(a, b) -> bool:
    """True when two models are the same equations (same class, equal attributes)."""
    if a is b:
        return True
    if type(a) is not type(b) or (va := vars(a)).keys() != (vb := vars(b)).keys():
        return False
    return all(_same(va[k], vb[k]) for k in va)


def _same(x, y) -> bool:
    """Equal values: arrays element-wise (shape too), dataclasses (a gate's settings), lists, tuples and
    dicts item by item; anything whose ``==`` is not a truth value (an array inside) is not equal."""
    if x is y:
        return True
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        return np.shape(x) == np.shape(y) and np.array_equal(x, y)
    if dataclasses.is_dataclass(x) and type(x) is type(y):
        return all(_same(getattr(x, f.name), getattr(y, f.name)) for f in dataclasses.fields(x))
    if isinstance(x, (list, tuple)) and type(x) is type(y):
        return len(x) == len(y) and all(_same(u, v) for u, v in zip(x, y))
    if isinstance(x, dict) and isinstance(y, dict):
        return x.keys() == y.keys() and all(_same(x[k], y[k]) for k in x)
    try:
        return bool(x == y)
    except (ValueError, TypeError):
        return False


def run_block(
    config: Config | dict, runs, data_dir=None, keep: bool = False, strict: bool = False, built: dict | None = None
) -> list[RunRecord]:
    """Compute and score runs ``runs`` of ``config`` (module docstring); one record per run, in run order.

    ``strict``: an error building or scoring a run is raised instead of recorded (``replay eval``);
    ``built``: {run: problem} already built by :func:`build_problem` for this configuration.
    Numerical exceptions inside a filter's step are that run's divergence; any other failure of the
    filter (a bug, ``sys.exit``, memory, a broken protocol) is its runs' failure (:mod:`replay.run.failures`).
    """
    c = config.as_dict() if isinstance(config, Config) else config
    if is_recorded(c["filter"]):
        return [_recorded_run(c, run, data_dir, keep, strict) for run in runs_of(c, runs)]
    results, problems = [], {}
    try:
        ds = resolve(c["dataset"])  # once for the block
    except Exception:  # noqa: BLE001 — each run fails with the error (build_problem)
        ds = False
    for run in runs:
        try:
            problems[run] = built[run] if built and run in built else build_problem(c, run, data_dir, ds)
        except Exception as err:  # recorded; the other runs go on
            if strict:
                raise
            results.append(failed(run, err))
    if not problems:
        return results
    groups = _groups(list(problems), problems)
    try:  # the filter; each group's model and priors under its noise settings, checked before any run
        flt = make_filter(c["filter"], **c["filter_params"])
        noisy = [apply_noise(flt, problems[g[0]].model, np.stack([problems[r].P0 for r in g])) for g in groups]
    except Exception as err:
        if strict:
            raise
        return results + [failed(run, err) for run in problems]
    estimates, wall = {}, {}
    for group, (model, P0) in zip(groups, noisy):
        ps = [problems[r] for r in group]
        t0 = perf_counter()
        try:
            out = flt.run_batch(
                model,
                np.stack([p.z for p in ps]),
                np.stack([p.x0 for p in ps]),
                P0,
                [filter_rng(c["seed"], r, c["filter"]) for r in group],
            )
            check_batch(c["filter"], out, ps)
        except BaseException as err:  # the filter's failure (any, sys.exit too): its runs failed
            if ends_run(err, strict):
                raise
            results += [dataclasses.replace(failed(r, err), problem=problems[r] if keep else None) for r in group]
            continue
        dt = (perf_counter() - t0) / len(group)
        for r, est in zip(group, out):
            estimates[r], wall[r] = est, dt
    for r in problems:
        if r not in estimates:
            continue
        try:
            results.append(score_record(c, problems[r], estimates[r], r, wall[r], keep))
        except Exception as err:
            if strict:
                raise
            results.append(failed(r, err))
    return sorted(results, key=lambda d: d.run)


def score_record(c: dict, problem, est, run: int, wall: float, keep: bool = False) -> RunRecord:
    """The record of one run: metrics (:func:`replay.scoring.metrics.run_metrics`) and the per-step table."""
    err = scorer.errors(problem, est)
    m, series = metrics.run_metrics(problem, est, c["alignment"], c["divergence_threshold"], err)
    m.update(likelihood.of_run(c, problem, est, series))  # replay tune's likelihood objective, where it exists
    cols = {"k": np.arange(len(est.x)), "t": np.asarray(problem.t[: len(est.x)], float)}
    cols.update({f"x{i}": est.x[:, i] for i in range(est.x.shape[1])})
    cols.update({f"P{i}{i}": est.P[:, i, i] for i in range(est.x.shape[1])})
    cols.update(covcols.covariance_columns(est.P, range(est.x.shape[1])))  # the whole state's covariance
    for j, axis in enumerate(problem.axis_names):
        cols[f"ref_{axis}"] = np.where(problem.truth_valid, problem.truth_position[:, j], np.nan)
        cols[f"err_{axis}"] = err["position"][:, j]
    for name in problem.truth_angles:
        cols[f"err_{name}"] = err[name]
    cols.update(series)
    m["seconds"] = wall
    meta = getattr(problem, "frame_meta", {})
    rec = RunRecord(run, DONE, m, cols, content_checked=meta.get("content_checked"))
    shared = marks.reference_inputs(meta, c["filter"])
    if shared and not (not is_recorded(c["filter"]) and (problem.params or {}).get("holdout")):
        rec.reference_input = shared  # a held-out fix is never fed: not scored against its own input
    ref = meta.get("reference") or {}
    if ref:  # where the reference comes from (replay/scoring/provenance.py), on every row
        rec.reference = ref["kind"]
    if ref.get("shares"):  # the reference shares a source with a fed input
        rec.reference_shares = ref["shares"]
    if ref.get("unconstrained"):  # an attitude angle nothing measures (replay/tasks/fusion_heading.py)
        rec.unconstrained = " | ".join(ref["unconstrained"])
    if est.info.get("error"):
        m["error"] = est.info["error"]
    if est.info.get("rejected") is not None:  # per-sensor outlier gating (replay.filters.gating)
        rec.rejected = dict(est.info["rejected"])
    if keep:
        rec.problem, rec.estimates, rec.errors = problem, est, err
    return rec


# ---------------------------------------------------------------- recorded estimates


def runs_of(config: dict, runs) -> list:
    """The runs of ``runs`` a configuration computes: all, or only run 0 for a recorded estimate."""
    return [r for r in runs if r == 0] if is_recorded(config["filter"]) else list(runs)


def _recorded_run(c: dict, run: int, data_dir, keep: bool, strict: bool) -> RunRecord:
    """The record of run 0 of a ``recorded:<name>`` configuration (never raises unless ``strict``)."""
    try:
        problem = build_problem(c, run, data_dir)
        scored, est, note = recorded_estimates(problem, c["filter"][len(RECORDED) :], c["filter_params"])
        rec = score_record(c, scored, est, run, float("nan"), keep)
        rec.metrics.update(unaligned_metrics(scored, est, c["divergence_threshold"]))
    except Exception as err:
        if strict:
            raise
        return failed(run, err)
    rec.note = note
    return rec
