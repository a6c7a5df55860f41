"""The entries of a campaign file, each checked alone: ``[[dataset]]``, ``[[filter]]`` and ``[task.NAME]``.

Every function raises ``file:line: key: message`` (:meth:`replay.campaign.spec._Where.error`)
and returns the entry canonical (every default filled in), ready to become configurations.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

from replay.campaign.checks import check_params
from replay.run.pipeline import plain as _plain
from replay.trajectory.recorded import recorded_params
from replay.util.errors import ReplayError, shown
from replay.data.views import NAMES as VIEW_NAMES, VIEW_PARAMS
from replay.util.lookup import resolve
from replay.tasks import TASKS
from replay.data import dataset_ref
from replay.data import registry
from replay.data.dataset_ref import DatasetRef
from replay.run.pipeline import load_frame
from replay.adapters.bags import resolve_mapping
from replay.filters import FILTERS
from replay.filters import make_filter


@dataclass
class DatasetEntry:
    """One ``[[dataset]]``: its id (a recording's absolute path for a path), canonical parameters,
    ``first``, tasks, recorded estimates ({name: association parameters}) and ``written``: the id as
    the file writes it (a recording's path relative to the file), which tables show."""

    id: str
    params: dict
    first: int | None
    tasks: list
    recorded: dict
    written: str = ""


def _class_of(registry: dict, name: str):

    return resolve(registry, name, "component")


def task_tables(where, doc: dict) -> dict:
    """The ``[task.NAME]`` tables: {task: parameters}, each checked against the task's declarations."""

    tables = doc.get("task", {})
    for tname, tp in tables.items():
        if tname not in TASKS:
            raise where.error(tname, f"unknown task (known: {', '.join(sorted(TASKS))})")
        check_params(where, f"task {shown(tname)}", _class_of(TASKS, tname).PARAMS, tp)
    return tables


def dataset(where, path: Path, entry: dict, data_dir: str | None) -> DatasetEntry:
    """One ``[[dataset]]`` checked (its keys and their types by their declaration,
    :data:`replay.campaign.spec.DATASET`): its id, tasks, ``first``, parameters and recorded estimates."""
    ref = _dataset_of(where, path, entry["id"])
    tasks = _tasks(where, entry.get("tasks", [(ref.entry and ref.entry.default_task) or "position"]))
    first = entry.get("first")
    if ref.kind == "file" and ref.locate(data_dir) is None:
        raise where.error(
            "id",
            f"dataset {ref.id} not found (set data_dir in [campaign], pass "
            f"--data-dir, or run `replay datasets fetch {ref.id}`)",
            ref.id,
        )
    params = _dataset_params(where, path, ref, dict(entry.get("params", {})))
    if (ref.is_sim and VIEW_NAMES & params.keys()) or "fault" in params:  # a view or fault it cannot take: now
        _load_once(where, ref.id, params, first, data_dir)
    recorded = _recorded(where, entry, ref.id, params, first, data_dir, ref.adapter)
    return DatasetEntry(ref.id, params, first, tasks, recorded, entry["id"] if ref.is_path else ref.id)


def _dataset_of(where, path: Path, ds_id: str):
    """The :class:`~replay.data.dataset_ref.DatasetRef` of an id: a registered one, or a recording's path
    (relative to the campaign file; its id becomes the absolute path)."""

    ref = _recording(where, path, ds_id)
    if ref is not None:
        return ref
    try:
        return dataset_ref.resolve(ds_id)
    except ReplayError as e:
        raise where.error("id", str(e), ds_id) from None


def _tasks(where, tasks) -> list:

    if not tasks:
        raise where.error("tasks", "empty list of tasks")
    for t in tasks:
        if not isinstance(t, str) or t not in TASKS:
            raise where.error("tasks", f"unknown task {shown(t)} (known: {', '.join(sorted(TASKS))})", t)
    return tasks


def _dataset_params(where, path: Path, ref, params: dict) -> dict:
    """A dataset's parameters canonical: a mapping relative to the campaign file made absolute, a
    simulator's and the views checked line by line, an adapter's options checked."""

    if isinstance(params.get("mapping"), str) and (path.parent / params["mapping"]).is_file():
        params["mapping"] = str((path.parent / params["mapping"]).resolve())  # relative to this file
    if ref.is_sim:
        own = {k: v for k, v in params.items() if k not in VIEW_NAMES}  # the views: checked below
        check_params(where, f"dataset {shown(ref.id)}", registry.generator(ref.entry).PARAMS, own)
        views = {k: v for k, v in params.items() if k not in own and k != "fault"}  # fault: below
        check_params(where, f"dataset {shown(ref.id)}", VIEW_PARAMS, views)
    try:
        return _plain(registry.check_params(ref.target, params, adapter=ref.adapter if ref.is_path else None))
    except ReplayError as e:
        raise where.error(next(iter(params), "params"), str(e)) from None


def _recording(where, path: Path, ds_id: str):
    """A ``[[dataset]]`` id that is a recording's path (relative to the campaign file): its reference
    (the absolute path, the adapter chosen from the file); None for a registered id."""

    if ds_id in registry.all_datasets() or not registry.is_path(str(path.parent / ds_id)):
        return None
    file = (path.parent / ds_id).resolve()
    if not file.exists():
        raise where.error("id", f"no such recording {file}", ds_id)
    try:
        adapter = registry.adapter_for(file)
    except ReplayError as e:
        raise where.error("id", str(e), ds_id) from None
    return DatasetRef(str(file), "path", path=file, adapter=adapter)


def _frame0(ds_id, ds_params: dict, first, data_dir):

    return load_frame(
        {"dataset": ds_id, "dataset_params": ds_params, "first": first, "seed": 0, "adapter": None}, 0, data_dir
    )


def _load_once(where, ds_id, ds_params: dict, first, data_dir):
    """Run 0's frame, so that a view it cannot take is refused before any unit."""
    try:
        return _frame0(ds_id, ds_params, first, data_dir)
    except ReplayError as e:
        raise where.error("params", str(e)) from None


def _recorded(where, entry: dict, ds_id, ds_params: dict, first, data_dir, adapter) -> dict:
    """{name: association parameters} of the recorded estimates a dataset entry scores: those
    named in ``recorded``, else every estimate its mapping declares (bags adapter only)."""
    declared = {}
    if adapter == "bags":
        try:
            if ds_params.get("mapping") is not None:
                declared = {e.name: e.params for e in resolve_mapping(ds_params["mapping"]).estimates}
            else:  # the proposed mapping: read the recording
                declared = {k: e.params for k, e in _frame0(ds_id, ds_params, first, data_dir).estimates.items()}
        except ReplayError as e:
            raise where.error("params", str(e)) from None
    chosen = entry.get("recorded", list(declared))
    out = {}
    for name in chosen:
        if not isinstance(name, str) or name not in declared:
            raise where.error(
                "recorded",
                f"no recorded estimate {shown(name)} in {ds_id} (its mapping's [estimates] "
                f"declare: {', '.join(declared) or 'none'})",
                name,
            )
        try:
            out[name] = _plain(recorded_params(name, None, declared[name]))
        except ReplayError as e:
            raise where.error("recorded", str(e), name) from None
    return out


def filters(where, entries: list, runs: int, max_units: int) -> list[tuple[str, dict]]:
    """Every ``[[filter]]`` with its grid expanded: [(name, canonical parameters)]."""
    out: list = []
    for entry in entries:
        out += _filter(where, entry, runs, len(out), max_units)
    return out


def _filter(where, entry: dict, runs: int, held: int, max_units: int) -> list[tuple[str, dict]]:
    """One ``[[filter]]``: one configuration per combination of its grid (``held``: those before it)."""

    name = entry["name"]  # its keys checked by their declaration (replay.campaign.spec.FILTER)
    if name not in FILTERS:
        raise where.error("name", f"unknown filter {shown(name)} (known: {', '.join(sorted(FILTERS))})", name)
    declared = _class_of(FILTERS, name).PARAMS
    base, grid = entry.get("params", {}), entry.get("grid", {})
    check_params(where, f"filter {shown(name)}", declared, base)
    for key, values in grid.items():
        if not isinstance(values, list):
            raise where.error(key, f"grid values must be a list, got {type(values).__name__}")
        if not values:
            raise where.error(key, "empty grid: give at least one value")
        for v in values:
            check_params(where, f"filter {shown(name)}", declared, {key: v})
    keys = list(grid)
    combos = math.prod(len(grid[k]) for k in keys)
    if (held + combos) * runs > max_units:  # before building them (a grid multiplies)
        raise where.error(
            keys[0] if keys else "filter",
            f"{held + combos} filter configurations x {runs} runs, "
            f"more than a campaign may hold ({max_units} units); split it",
        )
    return [
        (name, _made(where, name, {**base, **dict(zip(keys, combo))}))
        for combo in itertools.product(*(grid[k] for k in keys))
    ]


def _made(where, name: str, params: dict) -> dict:
    """The canonical parameters of filter ``name`` made with ``params`` (its constructor checks relations)."""

    try:
        return _plain(make_filter(name, **params).params())
    except ReplayError as e:
        raise where.error(name, str(e), name) from None
    except Exception as e:  # a constructor's own validation
        raise where.error(name, f"filter {shown(name)}: {e}", name) from None
