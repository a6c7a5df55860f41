"""Campaign files: datasets x tasks x filters (with parameter grids) x runs x seeds.

A campaign is a TOML file::

    [campaign]
    name = "example"          # names the default result directory runs/campaign-<name>
    runs = 50                 # Monte Carlo runs per configuration
    seed = 0                  # master seed (streams as in replay.evaluate)
    batch = 25                # runs per job (one batched filter call); optional
    alignment = "se3"         # ATE alignment: none, yaw, se3, sim3; optional
    divergence_threshold = 100.0   # m; a run whose position error exceeds it counts as diverged
    data_dir = "../data"      # where file datasets are looked for first (relative to this file)

    [[dataset]]
    id = "sim/auv-sonar"
    tasks = ["sonar"]         # default: the dataset's default task
    params = { steps = 100 }  # passed to the generator or adapter; views (rate, window, segment) for any
    first = 2000              # optional: only the first N samples

    [task.sonar]              # optional task parameters, for every dataset using the task
    yaw_rate = 0.25

    [[filter]]
    name = "pf"
    params = { resampling = "systematic" }
    grid = { n_particles = [200, 1000] }    # one configuration per combination

    [[dataset]]               # a recording by path (relative to this file), with its mapping
    id = "../data/ROS_example.bag"
    params = { mapping = "maps/evo_ros_example.toml" }
    recorded = ["ORB-SLAM"]   # recorded estimates scored as rows recorded:<name>; default: all

    [[fault]]                 # optional: a fault injected into every dataset (replay.campaign.fault_axis)
    channel = "gps"
    kind = "outage"
    t0 = 120
    sweep = { d = [0, 30, 60, 120] }   # one configuration per value: a robustness sweep

**Recorded estimates.** A dataset read by the bags adapter whose mapping declares
``[estimates]`` adds one configuration ``recorded:<name>`` per estimate (all by
default; ``recorded = [...]`` chooses, ``recorded = []`` none), beside the filters,
with the mapping's association settings as its parameters; it has one unit (run 0:
a recorded estimate is deterministic). A campaign may have no ``[[filter]]`` when it
scores recorded estimates only.

Everything is checked before any work starts (:func:`load`): the file's sections, keys,
their types and required keys by its one declaration :data:`FILE` (:mod:`replay.util.tomlschema`);
then a file that is not UTF-8 text, an unknown dataset, task, filter or parameter, a
``[campaign]`` value or a parameter of the wrong type or out of the bounds its
declaration states (:data:`CAMPAIGN_PARAMS`, :mod:`replay.util.params`: ``runs``
and ``batch`` at most :data:`replay.run.eval_options.MAX_RUNS` (one declaration with ``replay eval``),
``seed`` >= 0, ``divergence_threshold`` > 0),
more than :data:`MAX_UNITS` units, a ``name`` over :data:`MAX_NAME_BYTES` bytes, or an
empty grid, or a ``name`` that is not a plain name (a path separator, ``..``,
an absolute path: it would place the output outside the output root) raises
:class:`~replay.util.errors.ReplayError` with one line naming the file, the line and the key
(:mod:`replay.campaign.checks`; each entry: :mod:`replay.campaign.entries`).
Each configuration stores its parameters with
every default filled in (canonical), so ``{}`` and the defaults are the same
configuration, with the same hash.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from replay.campaign import entries, fault_axis
from replay.campaign.checks import MAX_NAME_BYTES, Where, check_name, check_params  # noqa: F401
from replay.run.eval_options import BY_NAME as EVAL
from replay.run.pipeline import Config
from replay.trajectory.recorded import RECORDED
from replay.run.pipeline import plain as _plain
from replay.util import tomlfile, tomlschema
from replay.util.errors import ReplayError
from replay.util.params import Param
from replay.util.tomlschema import Each, Table, Value
from replay.util.plugins import refuse_unallowed
from replay.tasks import make_task

MAX_UNITS = 10_000_000  # units (configurations x runs) of one campaign
CAMPAIGN_PARAMS = (  # the [campaign] table: the run options of replay eval and the API, one declaration
    Param("name", str, None, "names the default result directory runs/campaign-<name>", optional=True),
    EVAL["runs"],
    EVAL["seed"],
    EVAL["batch"],
    EVAL["alignment"],
    EVAL["divergence_threshold"],
    Param(
        "data_dir", str, None, "where file datasets are looked for first (relative to the campaign file)", optional=True
    ),
)
CAMPAIGN = Table("campaign", "[campaign]", CAMPAIGN_PARAMS, doc="the run options")
DATASET = Table(
    "dataset",
    "[[dataset]]",
    (
        Param("id", str, None, "a registered dataset id, or a recording's path (relative to this file)"),
        Value("tasks", (list,), "the tasks run on it (default: the dataset's default task)", item=str),
        Param("params", dict, None, "passed to the generator or adapter; the views rate, window, segment"),
        EVAL["first"],
        Value("recorded", (list,), "the recorded estimates scored (default: all; [] none)", item=str),
    ),
    required=("id",),
)
FILTER = Table(
    "filter",
    "[[filter]]",
    (
        Param("name", str, None, "a filter of replay list filters"),
        Param("params", dict, None, "its parameters (checked by its declarations)"),
        Param("grid", dict, None, "parameter = [values]: one configuration per combination"),
    ),
    required=("name",),
)
TUNE = Table(  # replay tune at scale: the rest is checked by replay.tune.campaign
    "tune",
    "[tune]",
    (
        Value("filters", (list,), "the filters tuned (default: the campaign's [[filter]] names)", item=str),
        Param("trials", int, 50, "trials per filter"),
        Param("objective", str, "mean_rmse", "as --objective"),
        Param("split", dict, None, "{ segment = 0.6 }, { seeds = S } or { train = [ids], test = [ids] }"),
        Param("space", dict, None, "FILTER.PARAM = SPEC (replay.tune.space)"),
        Param("allow_overlap", bool, False, "allow the train and test data to overlap"),
    ),
    doc="replay tune at scale (replay.tune.campaign)",
)
FAULT = Table(  # a fault of replay.data.faults: its channel, kind and parameters are checked by faults.check
    "fault", "[[fault]]", open=True, expect="a table (channel, kind, the kind's parameters, sweep)"
)
FILE = Table(  # the one declaration of a campaign file (entries.py, fault_axis.py and tune check the rest)
    "campaign file",
    "",
    (
        CAMPAIGN,
        Each("dataset", DATASET, array=True, doc="the datasets"),
        Each("task", Table("task", "[task.{name}]", open=True), doc="task parameters (the task's declarations)"),
        Each("filter", FILTER, array=True, doc="the filters"),
        TUNE,
        Each("fault", FAULT, array=True, doc="faults injected into every dataset (replay.campaign.fault_axis)"),
    ),
)
SECTIONS = tuple(FILE.known())
_Where = Where  # the name it had


@dataclass
class Campaign:
    path: Path
    name: str
    runs: int
    seed: int
    batch: int
    data_dir: str | None
    configs: list[Config] = field(default_factory=list)
    tune: dict | None = None  # the [tune] table, checked by replay.tune.campaign (replay tune at scale)
    where: object = None  # finds a key's line for messages about the file
    names: dict = field(default_factory=dict)  # {a recording's absolute id: its id as the file writes it}


def load(path, allow_modules=(), reader: str = "a campaign file") -> Campaign:
    """Read and check a campaign file; returns its configurations (no work done). A filter or task
    named ``package.module:Class`` is refused before anything is imported unless its module is in
    ``allow_modules`` (:func:`check_sources`)."""
    path = Path(path)
    doc, where = _read(path)
    check_sources(where, doc, allow_modules, reader)
    head = _head(where, doc, path)
    task_params = entries.task_tables(where, doc)
    datasets, filters = _entry_lists(where, doc)
    ds_entries = [entries.dataset(where, path, entry, head["data_dir"]) for entry in datasets]
    flt_entries = entries.filters(where, filters, head["runs"], MAX_UNITS)
    if not flt_entries and not any(e.recorded for e in ds_entries):
        raise where.error(
            "filter", "the campaign needs at least one [[filter]] (or a [[dataset]] with recorded estimates)"
        )
    extras = fault_axis.variants(where, doc)  # [[fault]] tables: one fault list per sweep combination
    fault_axis.check_frames(where, ds_entries, extras, head["data_dir"])
    configs = [
        Config(
            ds.id,
            fault_axis.with_faults(ds.params, extra),
            ds.first,
            t,
            canonical,
            name,
            fp,
            head["seed"],
            head["alignment"],
            head["divergence_threshold"],
        )
        for ds in ds_entries
        for extra in extras
        for t, canonical in _tasks(where, ds.tasks, task_params)
        for name, fp in flt_entries + [(RECORDED + k, v) for k, v in ds.recorded.items()]
    ]
    runs = head["runs"]
    if len(configs) * runs > MAX_UNITS:
        raise where.error(
            "runs",
            f"{len(configs)} configurations x {runs} runs = {len(configs) * runs} units, "
            f"more than a campaign may hold ({MAX_UNITS}); split it",
        )
    return Campaign(
        path,
        head["name"],
        runs,
        head["seed"],
        head["batch"],
        head["data_dir"],
        configs,
        doc.get("tune"),
        where,
        {ds.id: ds.written for ds in ds_entries if ds.written != ds.id},
    )


def _names(doc: dict) -> list[tuple[str, str, object]]:
    """(key, kind, name) of every filter and task the file names: ``[[filter]]``, ``[[dataset]]`` tasks,
    ``[task.NAME]`` tables and the ``[tune]`` filters (their shapes are checked later)."""
    lists = lambda v: v if isinstance(v, list) else []  # noqa: E731
    out = [("name", "filter", f.get("name")) for f in lists(doc.get("filter")) if isinstance(f, dict)]
    for d in lists(doc.get("dataset")):
        out += [("tasks", "task", t) for t in lists(d.get("tasks") if isinstance(d, dict) else None)]
    out += [("task", "task", t) for t in (doc.get("task") if isinstance(doc.get("task"), dict) else {})]
    tune = doc.get("tune") if isinstance(doc.get("tune"), dict) else {}
    return out + [("filters", "filter", n) for n in lists(tune.get("filters"))]


def check_sources(where, doc: dict, allow_modules=(), reader: str = "a campaign file") -> None:
    """The rule of ``replay rerun`` (:func:`replay.util.plugins.refuse_unallowed`) for every filter and
    task a campaign file names: a ``module:Class`` of a module not allowed is refused, nothing imported."""
    for key, kind, name in _names(doc):
        refuse_unallowed(name, allow_modules, f"{where.path}:{where.line(key, name)}: {key}", kind, reader)


def _read(path: Path) -> tuple[dict, Where]:
    """The parsed TOML of a campaign file and its :class:`Where`, checked by its declaration :data:`FILE`."""
    doc, text = tomlfile.load(path, "a campaign file")
    where = Where(path, text)
    tomlschema.check(FILE, doc, lambda key, text: ReplayError(f"{path}:{where.line(key)}: {text}"))
    return doc, where


def _head(where, doc: dict, path: Path) -> dict:
    """The ``[campaign]`` table checked (:data:`CAMPAIGN_PARAMS`), every default filled in, ``name``
    defaulting to the file's stem and ``data_dir`` made absolute (relative to the file)."""
    head = doc.get("campaign", {})  # checked by its declaration (FILE)
    out = {p.name: p.check(head[p.name]) if p.name in head else p.default for p in CAMPAIGN_PARAMS}
    out["name"] = head.get("name", path.stem)
    check_name(where, out["name"])
    if out["data_dir"] is not None:
        out["data_dir"] = str((path.parent / out["data_dir"]).resolve())
    return out


def _entry_lists(where, doc: dict) -> tuple[list, list]:
    """The ``[[dataset]]`` and ``[[filter]]`` lists: at least one dataset, and a filter unless the
    datasets may score recorded estimates alone."""
    datasets = doc.get("dataset", [])
    if not isinstance(datasets, list) or not datasets:
        raise where.error("dataset", "the campaign needs at least one [[dataset]]")
    filters = doc.get("filter", [])
    maybe_recorded = any(
        isinstance(d, dict) and (d.get("recorded") or "mapping" in (d.get("params") or {})) for d in datasets
    )  # recorded estimates alone need no [[filter]]
    if not isinstance(filters, list) or not (filters or maybe_recorded):
        raise where.error("filter", "the campaign needs at least one [[filter]]")
    return datasets, filters


def _tasks(where, tasks: list, task_params: dict) -> list[tuple[str, dict]]:
    """(task, canonical parameters) of each task of a dataset entry."""

    out = []
    for t in tasks:
        try:
            out.append((t, _plain(make_task(t, **task_params.get(t, {})).params())))
        except ReplayError as e:
            raise where.error(t, str(e), t) from None
    return out
