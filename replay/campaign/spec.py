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

**Recorded estimates.** A dataset read by the bags adapter whose mapping declares
``[estimates]`` adds one configuration ``recorded:<name>`` per estimate (all by
default; ``recorded = [...]`` chooses, ``recorded = []`` none), beside the filters,
with the mapping's association settings as its parameters; it has one unit (run 0:
a recorded estimate is deterministic). A campaign may have no ``[[filter]]`` when it
scores recorded estimates only.

Everything is checked before any work starts (:func:`load`): a file that is not
UTF-8 text, an unknown section, key, dataset, task, filter or parameter, a
``[campaign]`` value or a parameter of the wrong type or out of the bounds its
declaration states (:data:`CAMPAIGN_PARAMS`, :mod:`replay.util.params`: ``runs``
and ``batch`` at most :data:`replay.run.eval_options.MAX_RUNS` (one declaration with ``replay eval``),
``seed`` >= 0, ``divergence_threshold`` > 0),
more than :data:`MAX_UNITS` units, a ``name`` over :data:`MAX_NAME_BYTES` bytes, or an
empty grid, or a ``name`` that is not a plain name (a path separator, ``..``,
an absolute path: it would place the output outside the output root) raises
:class:`~replay.util.errors.ReplayError` with one line naming the file, the line and the key.
Each configuration stores its parameters with
every default filled in (canonical), so ``{}`` and the defaults are the same
configuration, with the same hash.
"""
from __future__ import annotations

import itertools
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from replay.run.eval_options import EVAL_OPTIONS
from replay.util.errors import ReplayError
from replay.util.params import Param
from replay.run.pipeline import Config
from replay.trajectory.recorded import RECORDED, recorded_params
from replay.run.pipeline import plain as _plain
from replay.data.views import NAMES as VIEW_NAMES, VIEW_PARAMS

MAX_UNITS = 10_000_000  # units (configurations x runs) of one campaign
MAX_NAME_BYTES = 240  # the name makes the directory runs/campaign-<name> (file names: 255 bytes)
_EVAL = {p.name: p for p in EVAL_OPTIONS}  # one declaration with replay eval and the API
CAMPAIGN_PARAMS = (  # the [campaign] table, checked by replay.util.params
    Param("name", str, None, "names the default result directory runs/campaign-<name>", optional=True),
    _EVAL["runs"], _EVAL["seed"], _EVAL["batch"], _EVAL["alignment"], _EVAL["divergence_threshold"],
    Param("data_dir", str, None, "where file datasets are looked for first (relative to the campaign file)",
          optional=True),
)
CAMPAIGN_KEYS = {p.name: p.type for p in CAMPAIGN_PARAMS}
DATASET_KEYS = {"id": str, "tasks": list, "params": dict, "first": int, "recorded": list}
FILTER_KEYS = {"name": str, "params": dict, "grid": dict}


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


class _Where:
    """Finds the line of a key in the campaign text for error messages."""

    def __init__(self, path: Path, text: str):
        self.path, self.lines = path, text.splitlines()

    def line(self, key: str, value=None) -> int:
        pats = []
        if value is not None and isinstance(value, str):
            pats.append(re.compile(re.escape(f'"{value}"') + "|" + re.escape(f"'{value}'")))
        pats.append(re.compile(r"(^|[\s{,\[.])" + re.escape(str(key)) + r"\s*[=\]]"))
        for pat in pats:
            for i, text in enumerate(self.lines, 1):
                if pat.search(text.split("#", 1)[0]):
                    return i
        return 1

    def error(self, key: str, what: str, value=None) -> ReplayError:
        return ReplayError(f"{self.path}:{self.line(key, value)}: {key}: {what}")


def check_name(where, name: str) -> None:
    """A campaign name must be a plain name: it becomes the directory ``runs/campaign-<name>``,
    and a separator, ``..`` or an absolute path would place the output elsewhere."""
    seps = {"/", "\\", os.sep} | ({os.altsep} if os.altsep else set())
    bad = ("it is empty" if not name.strip() else
           "it is an absolute path" if os.path.isabs(name) else
           "it contains a path separator" if any(c in name for c in seps) else
           "it is . or .." if name in (".", "..") else
           "it contains a control character" if any(ord(c) < 32 or ord(c) == 127 for c in name) else
           f"it is {len(name.encode())} bytes long, at most {MAX_NAME_BYTES}" if len(name.encode()) > MAX_NAME_BYTES
           else None)
    if bad:
        shown = name if len(name) <= 60 else name[:40] + "..."
        raise where.error("name", f"{shown!r} is not a plain name ({bad}; the output would not be "
                                  f"runs/campaign-<name>): use letters, digits, '-', '_' or '.'", name)


def _check_type(where, key, value, typ):
    ok = isinstance(value, typ) and not (typ in (int, float) and isinstance(value, bool))
    if typ is float and isinstance(value, int) and not isinstance(value, bool):
        ok = True
    if not ok:
        raise where.error(key, f"expected {typ.__name__}, got {type(value).__name__} {value!r}")


def _check_keys(where, table: dict, allowed: dict, what: str):
    for key, value in table.items():
        if key not in allowed:
            raise where.error(key, f"unknown key in {what} (known: {', '.join(sorted(allowed))})")
        _check_type(where, key, value, allowed[key])


def check_params(where, owner: str, declarations, params: dict) -> None:
    """Each parameter against its declaration: an unknown name, a wrong type or a value out of
    bounds -> ``file:line: key: message``."""
    known = {p.name: p for p in declarations}
    for key, value in params.items():
        if key not in known:
            raise where.error(key, f"{owner} has no parameter {key!r} (known: {', '.join(known) or 'none'})")
        try:
            known[key].check(value, owner)
        except ReplayError as e:
            raise where.error(key, str(e), value) from None


def _class_of(registry: dict, name: str):
    from replay.util.lookup import resolve

    return resolve(registry, name, "component")


def load(path) -> Campaign:
    """Read and check a campaign file; returns its configurations (no work done)."""
    from replay.data import registry
    from replay.filters import FILTERS
    from replay.tasks import TASKS, make_task
    from replay.filters import make_filter

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise ReplayError(f"{path}: cannot read campaign file: {e.strerror}") from None
    except UnicodeDecodeError as e:
        raise ReplayError(f"{path}: not a campaign file (not UTF-8 text: byte {e.start}); a campaign "
                          "is a TOML file") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ReplayError(f"{path}: not valid TOML: {e}") from None
    where = _Where(path, text)
    for key in doc:
        if key not in ("campaign", "dataset", "task", "filter", "tune"):
            raise where.error(key, "unknown section (known: campaign, dataset, task, filter, tune)")
    if "tune" in doc and not isinstance(doc["tune"], dict):
        raise where.error("tune", "expected a table [tune]")
    head = doc.get("campaign", {})
    if not isinstance(head, dict):
        raise where.error("campaign", "expected a table [campaign]")
    for key in head:
        if key not in CAMPAIGN_KEYS:
            raise where.error(key, f"unknown key in [campaign] (known: {', '.join(sorted(CAMPAIGN_KEYS))})")
    check_params(where, "[campaign]", CAMPAIGN_PARAMS, head)
    check_name(where, head.get("name", path.stem))
    runs, seed, batch = head.get("runs", 1), head.get("seed", 0), head.get("batch", 25)
    alignment = head.get("alignment", "se3")
    threshold = head.get("divergence_threshold")
    threshold = float(threshold) if threshold is not None else None
    data_dir = head.get("data_dir")
    if data_dir is not None:
        data_dir = str((path.parent / data_dir).resolve())

    task_params = doc.get("task", {})
    for tname, tp in task_params.items():
        if tname not in TASKS:
            raise where.error(tname, f"unknown task (known: {', '.join(sorted(TASKS))})")
        if not isinstance(tp, dict):
            raise where.error(tname, "expected a table of task parameters")
        check_params(where, f"task {tname!r}", _class_of(TASKS, tname).PARAMS, tp)

    datasets = doc.get("dataset", [])
    if not isinstance(datasets, list) or not datasets:
        raise where.error("dataset", "the campaign needs at least one [[dataset]]")
    filters = doc.get("filter", [])
    maybe_recorded = any(isinstance(d, dict) and (d.get("recorded") or "mapping" in (d.get("params") or {}))
                         for d in datasets)  # recorded estimates alone need no [[filter]]
    if not isinstance(filters, list) or not (filters or maybe_recorded):
        raise where.error("filter", "the campaign needs at least one [[filter]]")

    ds_entries = []
    for entry in datasets:
        _check_keys(where, entry, DATASET_KEYS, "[[dataset]]")
        if "id" not in entry:
            raise where.error("dataset", "every [[dataset]] needs an id")
        ds_id = entry["id"]
        ds = _recording(where, path, ds_id)
        if ds is None:
            try:
                ds = registry.get(ds_id)
            except ReplayError as e:
                raise where.error("id", str(e), ds_id) from None
        else:
            ds_id = ds.id
        tasks = entry.get("tasks", [ds.default_task or "position"])
        if not tasks:
            raise where.error("tasks", "empty list of tasks")
        for t in tasks:
            if not isinstance(t, str) or t not in TASKS:
                raise where.error("tasks", f"unknown task {t!r} (known: {', '.join(sorted(TASKS))})", t)
        first = entry.get("first")
        if first is not None and first < 1:
            raise where.error("first", f"must be at least 1 (got {first})")
        if ds.kind == "file" and ds.manifest and registry.locate(ds, data_dir) is None:
            raise where.error("id", f"dataset {ds_id} not found (set data_dir in [campaign], pass "
                                    f"--data-dir, or run `replay datasets fetch {ds_id}`)", ds_id)
        ds_params = dict(entry.get("params", {}))
        if isinstance(ds_params.get("mapping"), str) and (path.parent / ds_params["mapping"]).is_file():
            ds_params["mapping"] = str((path.parent / ds_params["mapping"]).resolve())  # relative to this file
        if ds.kind == "sim":
            own = {k: v for k, v in ds_params.items() if k not in VIEW_NAMES}  # the views: checked below
            check_params(where, f"dataset {ds_id!r}", registry.generator(ds).PARAMS, own)
            check_params(where, f"dataset {ds_id!r}", VIEW_PARAMS, {k: v for k, v in ds_params.items() if k not in own})
        try:
            ds_params = _plain(registry.check_params(ds if ds.manifest else ds.file, ds_params))
        except ReplayError as e:
            raise where.error(next(iter(ds_params), "params"), str(e)) from None
        if ds.kind == "sim" and VIEW_NAMES & ds_params.keys():  # a view the simulation cannot take: now
            _load_once(where, ds_id, ds_params, first, data_dir)
        recorded = _recorded(where, entry, ds_id, ds_params, first, data_dir, ds.adapter)
        ds_entries.append((ds_id, ds_params, first, tasks, recorded))

    flt_entries = []
    for entry in filters:
        _check_keys(where, entry, FILTER_KEYS, "[[filter]]")
        name = entry.get("name")
        if name is None:
            raise where.error("filter", "every [[filter]] needs a name")
        if name not in FILTERS:
            raise where.error("name", f"unknown filter {name!r} (known: {', '.join(sorted(FILTERS))})", name)
        declared = _class_of(FILTERS, name).PARAMS
        base, grid = entry.get("params", {}), entry.get("grid", {})
        check_params(where, f"filter {name!r}", declared, base)
        for key, values in grid.items():
            if not isinstance(values, list):
                raise where.error(key, f"grid values must be a list, got {type(values).__name__}")
            if not values:
                raise where.error(key, "empty grid: give at least one value")
            for v in values:
                check_params(where, f"filter {name!r}", declared, {key: v})
        keys = list(grid)
        combos = math.prod(len(grid[k]) for k in keys)
        if (len(flt_entries) + combos) * runs > MAX_UNITS:  # before building them (a grid multiplies)
            raise where.error(keys[0] if keys else "filter", f"{len(flt_entries) + combos} filter configurations x "
                              f"{runs} runs, more than a campaign may hold ({MAX_UNITS} units); split it")
        for combo in itertools.product(*(grid[k] for k in keys)):
            params = {**base, **dict(zip(keys, combo))}
            try:
                flt = make_filter(name, **params)
            except ReplayError as e:
                raise where.error(name, str(e), name) from None
            except Exception as e:  # a constructor's own validation
                raise where.error(name, f"filter {name!r}: {e}", name) from None
            flt_entries.append((name, _plain(flt.params())))

    if not flt_entries and not any(e[4] for e in ds_entries):
        raise where.error("filter", "the campaign needs at least one [[filter]] (or a [[dataset]] with "
                                    "recorded estimates)")
    configs = []
    for ds_id, ds_params, first, tasks, recorded in ds_entries:
        for t in tasks:
            tp = task_params.get(t, {})
            try:
                canonical = _plain(make_task(t, **tp).params())
            except ReplayError as e:
                raise where.error(t, str(e), t) from None
            rows = flt_entries + [(RECORDED + k, v) for k, v in recorded.items()]
            for name, fp in rows:
                configs.append(Config(ds_id, ds_params, first, t, canonical, name, fp, seed,
                                      alignment, threshold))
    if len(configs) * runs > MAX_UNITS:
        raise where.error("runs", f"{len(configs)} configurations x {runs} runs = {len(configs) * runs} units, "
                                  f"more than a campaign may hold ({MAX_UNITS}); split it")
    return Campaign(path, head.get("name", path.stem), runs, seed, batch, data_dir, configs, doc.get("tune"), where)


def _recording(where, path: Path, ds_id: str):
    """A ``[[dataset]]`` id that is a recording's path (relative to the campaign file): a
    stand-in Dataset (``manifest`` empty, ``file`` the absolute path); None for a registered id."""
    from replay.data import registry

    if ds_id in registry.all_datasets() or not registry.is_path(str(path.parent / ds_id)):
        return None
    file = (path.parent / ds_id).resolve()
    if not file.exists():
        raise where.error("id", f"no such recording {file}", ds_id)
    try:
        adapter = registry.adapter_for(file)
    except ReplayError as e:
        raise where.error("id", str(e), ds_id) from None
    return registry.Dataset(id=str(file), kind="file", adapter=adapter, file=str(file))


def _load_once(where, ds_id, ds_params: dict, first, data_dir):
    """Run 0's frame, so that a view it cannot take is refused before any unit."""
    from replay.run.pipeline import load_frame

    try:
        return load_frame({"dataset": ds_id, "dataset_params": ds_params, "first": first, "seed": 0,
                           "adapter": None}, 0, data_dir)
    except ReplayError as e:
        raise where.error("params", str(e)) from None


def _recorded(where, entry: dict, ds_id, ds_params: dict, first, data_dir, adapter) -> dict:
    """{name: association parameters} of the recorded estimates a dataset entry scores: those
    named in ``recorded``, else every estimate its mapping declares (bags adapter only)."""
    declared = {}
    if adapter == "bags":
        try:
            if ds_params.get("mapping") is not None:
                from replay.adapters.bags import resolve_mapping

                declared = {e.name: e.params for e in resolve_mapping(ds_params["mapping"]).estimates}
            else:  # the proposed mapping: read the recording
                from replay.run.pipeline import load_frame

                frame = load_frame({"dataset": ds_id, "dataset_params": ds_params, "first": first, "seed": 0,
                                    "adapter": None}, 0, data_dir)
                declared = {k: e.params for k, e in frame.estimates.items()}
        except ReplayError as e:
            raise where.error("params", str(e)) from None
    chosen = entry.get("recorded", list(declared))
    out = {}
    for name in chosen:
        if not isinstance(name, str) or name not in declared:
            raise where.error("recorded", f"no recorded estimate {name!r} in {ds_id} (its mapping's [estimates] "
                                          f"declare: {', '.join(declared) or 'none'})", name)
        try:
            out[name] = _plain(recorded_params(name, None, declared[name]))
        except ReplayError as e:
            raise where.error("recorded", str(e), name) from None
    return out
