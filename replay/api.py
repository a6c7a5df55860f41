"""The Python API, re-exported by ``replay`` (``import replay``; docs/python.md).

Every function takes its subject first and the rest by keyword only. Results are the
library's objects (:class:`replay.frame.Frame`, :class:`replay.run.evaluation.Evaluation`),
with DataFrame views (:mod:`replay.run.tables`, :mod:`replay.util.dataframes`) and
matplotlib figures (:mod:`replay.run.plots`); errors are one-line
:class:`replay.util.errors.ReplayError`.

Filters may be given as names (built-in, plugin, ``"module:Class"``), as
:class:`replay.filters.Filter` subclasses or as instances (their declared parameters
are used): a class is registered for this session under its ``name`` attribute (or its
class name in lower case). Such a filter runs in this process (``evaluate``); a
campaign's worker processes need a packaged plugin or a ``"module:Class"`` name.
"""

from __future__ import annotations

import csv
import importlib
import inspect
import json
import os
from pathlib import Path

from replay.api_args import ARGS, checked, default
from replay.data import plugins, registry
from replay.data.plugins import ADAPTERS, dataset_entries
from replay.run import tables
from replay.run.eval_options import DEFAULT_FILTERS, EvalOptions
from replay.filters import FILTERS, make_filter  # noqa: F401 — re-exported
from replay.run.plots import plot_errors, plot_paired, plot_rmse, plot_track  # noqa: F401 — re-exported
from replay.scoring import summary
from replay.trajectory import lengths as by_length
from replay.trajectory import load
from replay.trajectory import score_api
from replay.trajectory.score_options import ScoreOptions
from replay.trajectory.score_result import ScoreResult  # noqa: F401 — re-exported
from replay.tasks import TASKS, make_task  # noqa: F401 — re-exported
from replay.util.dataframes import frame_table, report_table  # noqa: F401 — re-exported
from replay.util.errors import ReplayError
from replay.util.plugins import NAME

# Kept lazy, in the functions that need them (import time after ``import replay.api``, measured): the
# evaluation pipeline (replay.run.evaluation 2.4 s, replay.filters.base 1.6 s, replay.run.pipeline 1.9 s),
# the campaign runner (replay.campaign.execute 2.6 s), the campaign store (replay.campaign.board, .store: 0.1 s), the
# MCAP export (replay.outputs.export_mcap, .export_safety: 0.15 s) and pandas: replay.load_frame pays for none of them.

__all__ = sorted(ARGS)  # the public names: replay.__all__ (tests/test_hostile_api.py checks both)


def load_frame(dataset, *, data_dir=None, seed=None, first: int | None = None, adapter: str | None = None, **params):
    """A dataset id (``"bohai/20220822_0_6"``, ``"sim/auv-sonar"``) or a file as a Frame.

    ``seed`` (an int or a ``numpy.random.Generator``) draws a simulated dataset;
    ``params`` are the simulator's parameters or the adapter's options (``replay list``).
    """
    return registry.load_frame(os.fspath(dataset), data_dir=data_dir, rng=seed, first=first, adapter=adapter, **params)


def evaluate(dataset, *, filters=DEFAULT_FILTERS, filter_params: dict | None = None, out=None, force=False, **options):
    """Run ``filters`` on ``dataset`` and score them: an :class:`replay.run.evaluation.Evaluation`.

    ``filters``: names (``"ekf,ukf"`` or a list), Filter classes or instances (module
    docstring). ``options``: the fields of :class:`replay.run.eval_options.EvalOptions` (``task``, ``runs``,
    ``seed``, ``first``, ``data_dir``, ``task_params``, ``dataset_params``, ``adapter``,
    ``alignment``, ``divergence_threshold``, ``baseline``, ...), the options of ``replay eval``, and
    ``progress``; they become one record, passed whole to :func:`replay.run.evaluation.evaluate`.
    ``out``: also write it as ``replay eval --out`` does (leaderboard, estimates, manifest; ``force``:
    replace an earlier eval output there), through :func:`replay.outputs.eval_job.run_eval`, the command's
    own call: everything refused before the computation, the set written whole.
    """
    names, params = filter_names(filters, filter_params)
    progress = options.pop("progress", None)
    o = EvalOptions(filters=names, filter_params=params, **options)
    if out is None:
        # lazy: module comment
        from replay.run.evaluation import evaluate as run  # noqa: PLC0415

        return run(os.fspath(dataset), o, progress=progress)
    # lazy: module comment
    from replay.outputs.eval_job import EvalReport, OutputRequest, run_eval  # noqa: PLC0415

    return run_eval(os.fspath(dataset), o, OutputRequest(out, force=force), EvalReport(progress)).evaluation


def filter_names(filters, filter_params: dict | None = None) -> tuple[list, dict]:
    """(names, filter_params) of ``filters`` given as names, classes or instances."""
    if isinstance(filters, str):
        filters = [f.strip() for f in filters.split(",") if f.strip()]
    # lazy: module comment
    from replay.filters.base import Filter  # noqa: PLC0415

    if not isinstance(filters, (list, tuple)) or not all(
        isinstance(f, (str, Filter)) or inspect.isclass(f) and issubclass(f, Filter) for f in filters
    ):
        raise ReplayError(
            f"filters must be filter names (\"ekf,ukf\" or a list), Filter classes or instances (got {filters!r:.80})"
        )
    if filter_params is not None and not (
        isinstance(filter_params, dict)
        and all(isinstance(k, str) and isinstance(v, dict) for k, v in filter_params.items())
    ):
        raise ReplayError(
            f"filter_params must be an object {{filter: {{parameter: value}}}} (got {filter_params!r:.80})"
        )
    names, params = [], {k: dict(v) for k, v in (filter_params or {}).items()}
    for item in filters:
        if isinstance(item, str):
            names.append(item)
            continue
        cls = item if inspect.isclass(item) else type(item)
        name = register_filter(cls)
        if not inspect.isclass(item):  # an instance: its declared parameters
            if name in names:
                raise ReplayError(
                    f"filter {name!r} is given twice: evaluate runs one configuration per filter "
                    "(a parameter grid is a campaign: replay.run_campaign)"
                )
            params[name] = {**item.params(), **params.get(name, {})}
        names.append(name)
    return names, params


def _register(registry_, obj, name):
    if name is None:
        own = obj.__dict__.get("name") if inspect.isclass(obj) else None
        name = own if isinstance(own, str) and NAME.fullmatch(own) else obj.__name__.lower().replace("_", "-")
    try:
        if name in registry_ and registry_.load(name) is obj:  # already registered (built-in, plugin, session)
            return name
    except ReplayError:
        pass
    if name in registry_ and registry_.origin(name) == "registered in this session":
        registry_.unregister(name)  # replaced (a notebook cell run again)
    return registry_.register(name, obj)


def register_filter(cls, *, name: str | None = None) -> str:
    """Register a :class:`replay.filters.Filter` subclass for this session; returns its name
    (``name``, else the class's own ``name`` attribute, else its class name in lower case)."""
    return _register(FILTERS, cls, name)


def register_task(cls, *, name: str | None = None) -> str:
    """Register a :class:`replay.tasks.Task` subclass for this session; returns its name."""
    return _register(TASKS, cls, name)


def run_campaign(
    campaign,
    *,
    out,
    workers: int | None = None,
    data_dir=None,
    quiet: bool = True,
    retry_failed: bool = False,
    allow_modules=(),
):
    """Run a campaign file (TOML, ``campaigns/example.toml``) into ``out``: its leaderboard as a
    DataFrame (one row per configuration; ``df.attrs["counts"]``: units computed, failed, ...).
    A filter or task the file names as ``package.module:Class`` is refused before anything is
    imported unless ``allow_modules`` holds its module (a class of this session: register it)."""

    # lazy: module comment
    from replay.campaign import execute, lock, spec  # noqa: PLC0415

    c = spec.load(campaign, allow_modules)
    lock.output_set(out, [c.data_dir, data_dir], what="out").check()  # the rule of the CLI's --out
    how = execute.RunOptions(workers=workers, data_dir=data_dir, quiet=quiet, retry_failed=retry_failed)
    counts = execute.run(c, Path(out), how)
    df = _rows(counts.pop("rows"))
    df.attrs["counts"] = counts
    return df


def campaign_results(out, *, runs: bool = False):
    """A result directory (a campaign's, or a ``replay eval`` output) as one DataFrame: its
    leaderboard rows; ``runs=True``: one row per configuration and run with every per-run metric
    (a campaign's units, or an eval output's ``runs.csv``)."""
    # lazy: module comment
    from replay.campaign import board  # noqa: PLC0415

    if not runs:
        return _rows(board.read_dir(out))
    # lazy: module comment
    import pandas as pd  # noqa: PLC0415

    # lazy: module comment
    from replay.campaign.store import Store  # noqa: PLC0415

    if not Path(out).is_dir():
        raise ReplayError(
            f"{out}: {'not a directory' if Path(out).exists() else 'no such directory'}: runs=True reads the "
            "directory of a campaign or of a replay eval output"
        )
    if not (Path(out) / "units").is_dir():
        return _eval_runs(Path(out))
    store, rows = Store(out), []
    for h, cfg in store.configs():
        for rec in store.records(h):
            rows.append(
                {
                    "dataset": cfg["dataset"],
                    "task": cfg["task"],
                    "filter": cfg["filter"],
                    "params": cfg["filter_params"],
                    "config_hash": h,
                    "run": rec.run,
                    "status": rec.status,
                    **(rec.metrics or {}),
                }
            )
    return pd.DataFrame(rows)


def _eval_runs(out):
    """The per-run rows of a ``replay eval`` output (``runs.csv``; floats read back bit for bit)."""

    # lazy: module comment
    import pandas as pd  # noqa: PLC0415

    path = out / "runs.csv"
    if not path.is_file():
        what = (
            "a replay eval output written before runs.csv (rerun it)"
            if (out / "manifest.json").is_file()
            else "not a campaign or replay eval output"
        )
        raise ReplayError(f"{out}: no units/ and no runs.csv: {what}")
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        rows = list(reader)
    lacking = [c for c in ("filter", "run", "status") if c not in (reader.fieldnames or [])]
    if lacking or not rows:
        what = f"its header lacks {', '.join(lacking)}" if lacking else "a header, no row"
        raise ReplayError(f"{path}: not the runs of a replay eval output ({what})")

    def cell(k, v):
        if k == "params":
            return json.loads(v)
        if k in ("dataset", "task", "filter", "config_hash", "status") or v in ("True", "False", ""):
            return {"True": True, "False": False, "": None}.get(v, v)
        try:
            return int(v) if k == "run" else float(v)
        except ValueError:
            return v

    return pd.DataFrame([{k: cell(k, v) for k, v in row.items()} for row in rows])


def _rows(rows):
    # lazy: module comment
    import pandas as pd  # noqa: PLC0415

    return pd.DataFrame(rows, columns=summary.columns(rows) if rows else None)


def load_trajectory(source, **options):
    """A trajectory from a file or a bag topic: :func:`replay.trajectory.load`."""

    return load(source, **options)


def export_mcap(evaluation, path, *, run: int = 0, data_dir=None) -> int:
    """Write run ``run`` of an evaluation (reference, each filter's track and error, the sensors)
    as a Foxglove MCAP file; returns the number of messages. ``data_dir``: where the dataset
    was found (the frame is read again). An existing file is replaced only if replay wrote it."""
    # lazy: module comment
    from replay.outputs.export_mcap import write_mcap  # noqa: PLC0415

    # lazy: module comment
    from replay.outputs.export_safety import check_target, dataset_inputs  # noqa: PLC0415

    # lazy: module comment
    from replay.run.pipeline import load_frame as frame_of_run  # noqa: PLC0415

    cfg = evaluation.results[0].config
    check_target(
        path, dataset_inputs(cfg["dataset"], (cfg.get("dataset_params") or {}).get("mapping"), data_dir), "mcap"
    )
    frame = frame_of_run(cfg, run, data_dir)
    problem = tables.result(evaluation, evaluation.results[0].name).records[run].problem
    estimates = {}
    for res in evaluation.results:
        est = res.estimates[run]
        estimates[res.name] = {
            "t": evaluation.t[: len(est.x)],
            "x": est.x,
            "err": res.errors[run]["position"],
            "P": est.P,
        }
    return write_mcap(path, frame, problem, estimates)


def list_plugins():
    """Every plugin (entry point) of the four groups, and every problem: a DataFrame with
    ``kind, name, origin, target, problem`` (``replay list plugins`` prints the same)."""
    # lazy: module comment
    import pandas as pd  # noqa: PLC0415

    return pd.DataFrame(plugin_rows(), columns=["kind", "name", "origin", "target", "problem"])


def plugin_rows() -> list[dict]:

    rows = []
    for kind, reg in (("filter", FILTERS), ("task", TASKS), ("adapter", ADAPTERS)):
        for name in reg:
            if reg.is_plugin(name):
                try:
                    reg.load(name)
                    problem = ""
                except ReplayError as err:
                    problem = str(err)
                rows.append(
                    {"kind": kind, "name": name, "origin": reg.origin(name), "target": reg[name], "problem": problem}
                )
        rows += [
            {"kind": kind, "name": "", "origin": "", "target": "", "problem": p}
            for p in reg.problems()
            if not any(r["problem"] == p for r in rows)
        ]
    found = registry.all_datasets()
    for ds_id, where, fields in dataset_entries()[0]:
        if ds_id in found:
            rows.append(
                {
                    "kind": "dataset",
                    "name": ds_id,
                    "origin": where.split(", ")[0][len("entry point of ") :],
                    "target": fields.get("generator") or fields.get("file", ""),
                    "problem": "",
                }
            )
    rows += [
        {"kind": "dataset", "name": "", "origin": "", "target": "", "problem": p} for p in registry.plugin_problems()
    ]
    return rows


def refresh_plugins() -> None:
    """Discover the installed plugins again (after ``pip install`` in a running session)."""

    importlib.invalidate_caches()
    FILTERS.refresh()
    TASKS.refresh()
    plugins.refresh()


# how the trajectories are read and named: the rest of replay.score's keywords are its ScoreOptions
SCORE_SOURCES = ("names", "trials", "fmt", "kitti_times", "columns", "time_unit")


def score(reference, estimates=None, **options) -> ScoreResult:
    """Score ``estimates`` against ``reference`` as ``replay score`` does: a :class:`ScoreResult`.

    ``reference``, ``estimates`` (one or a list): a trajectory file (TUM, KITTI, EuRoC, CSV),
    ``RECORDING:TOPIC``, ``RECORDING:tf:PARENT->CHILD``, a Trajectory or a DataFrame (``t, x, y, z``
    and optionally ``qx, qy, qz, qw``). The options are the CLI's long options (docs/evo.md), declared
    in ``replay.api_args.ARGS["score"]``: ``align`` none, yaw, se3 (evo's ``-a``), sim3 (``-as``) or
    scale (``-s``); ``pose_relation`` (``-r``, one or a list); ``rpe``, ``delta``, ``delta_unit``,
    ``delta_tol``, ``all_pairs``, ``pairs_from_reference`` (the RPE); ``fmt``, ``kitti_times``,
    ``columns``, ``time_unit`` (files); ``names``: one per estimate (default: the topic, else the file
    stem, else the trajectory's name); ``lengths`` (``"10%,20%"`` or a list of those strings),
    ``lengths_method``: the relative errors over lengths (``ScoreResult.lengths()``); evo's trajectory
    options ``sync_method``, ``t_start``, ``t_end``, ``downsample``, ``motion_filter`` ((metres,
    degrees)), ``project_to_plane`` (:mod:`replay.trajectory.prepare`); ``trials``: trials of one
    estimator each, ``{name: glob or [sources]}`` (or one glob, or a list of ``NAME=GLOB``;
    ``estimates`` may then be empty), scored as ``NAME/1``.. and aggregated (``ScoreResult.trials()``,
    :mod:`replay.trajectory.trials`). The options become one record (:class:`ScoreOptions`), the
    declarations' defaults filled in.
    """
    given = {k: options[k] if k in options else default(d) for k, d in ARGS["score"].items()}
    del given["reference"], given["estimates"]
    sources = {k: given.pop(k) for k in SCORE_SOURCES}
    relation, lengths = given.pop("pose_relation"), given.pop("lengths")
    if lengths is not None:
        lengths = by_length.parse(lengths if isinstance(lengths, str) else ",".join(f"{v:g}" for v in lengths))
    motion = given.pop("motion_filter")
    opts = ScoreOptions(
        **given,
        relations=list(dict.fromkeys([relation] if isinstance(relation, str) else relation)),
        lengths=lengths,
        motion_filter=None if motion is None else tuple(motion),
    )
    if "point_distance_error_ratio" in opts.relations and not opts.want_rpe:
        raise ReplayError("pose_relation point_distance_error_ratio is an RPE relation: add rpe=True (or a delta)")
    return score_api.score(reference, estimates, opts, **sources)


def _checked() -> None:
    """Every public function with its arguments checked first (:mod:`replay.api_args`)."""
    for name in __all__:
        globals()[name] = checked(name, globals()[name])


_checked()
