"""Adapters and datasets of other packages: the ``replay.adapters`` and ``replay.datasets`` entry points.

Filters and tasks have their registries beside their built-ins (``replay.filters.FILTERS``,
``replay.tasks.TASKS``); the adapters' is :data:`ADAPTERS` here (the built-in
``replay.adapters.ADAPTERS`` plus the plugins), used by :mod:`replay.data.registry`.

A ``replay.datasets`` entry point names a dataset id (``"example/cv-target"``) and
points at either

* a simulator: a function ``make_frame(rng, **params) -> Frame`` decorated with
  :func:`replay.sim.generator` (its declared parameters), optionally with the
  attributes ``DEFAULT_TASK``, ``DESCRIPTION``, ``LICENSE``, ``CITATION``; or
* a dict of manifest fields, as a ``[[dataset]]`` entry of ``datasets/*.toml``
  (``datasets/README.md``): a recording read by an adapter (``file``, ``adapter``,
  ``url``, ``sha256``, ...) or a simulator (``generator``).

:func:`dataset_entries` imports them (once per process) and returns their manifest
fields; :mod:`replay.data.registry` makes them datasets beside the manifests'. Every
problem is one line naming the plugin and its distribution (:mod:`replay.util.plugins`).
"""

from __future__ import annotations

import inspect
import re

from replay.adapters import ADAPTERS as BUILTIN_ADAPTERS
from replay.util.plugins import Registry, declaration_problem, describe, discover, load_target, one_line

GROUP = "replay.datasets"
DATASET_ID = re.compile(r"[A-Za-z0-9][\w.+-]*/[\w.+-]+(/[\w.+-]+)*")


def _check_adapter(obj):
    """What keeps ``obj`` from being an adapter ``load(path, *, option=...) -> Frame``, or None."""
    if inspect.isclass(obj) or not callable(obj):
        return f"is {describe(obj)}, not a function load(path, *, option=...) -> Frame"
    try:
        params = list(inspect.signature(obj).parameters.values())
    except (TypeError, ValueError):
        return None
    if not params or params[0].kind not in (params[0].POSITIONAL_ONLY, params[0].POSITIONAL_OR_KEYWORD):
        return "must take the path as its first parameter: load(path, *, option=...)"
    loose = [p.name for p in params[1:] if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD, p.VAR_POSITIONAL)]
    if loose:
        return f"its options must be keyword-only (after a *): {', '.join(loose)}"
    return None


ADAPTERS = Registry("adapter", BUILTIN_ADAPTERS, check=_check_adapter)

_CACHE: dict = {}


def refresh() -> None:
    """Forget the discovered adapters and datasets (after installing or removing a plugin)."""
    _CACHE.clear()
    ADAPTERS.refresh()


def dataset_entries(taken=()) -> tuple[list[tuple[str, str, dict]], dict, list]:
    """``([(id, where, manifest fields)], {id: conflict line}, [problem lines])`` of the dataset
    plugins; ``taken``: ids already defined (by the manifests), refused with a line each."""
    if "datasets" not in _CACHE:
        _CACHE["datasets"] = _discover()
    entries, conflicts, problems = _CACHE["datasets"]
    out, more = [], []
    for ds_id, where, fields in entries:
        if ds_id in taken:
            more.append(f"dataset {ds_id!r} ({where}): the id is taken by a dataset of replay's manifests; ignored")
        else:
            out.append((ds_id, where, fields))
    return out, conflicts, problems + more


def _discover():
    plugins, conflicts, problems = discover(GROUP, "dataset", valid=DATASET_ID.fullmatch)
    entries = []
    for ds_id, p in plugins.items():
        where = p.where
        try:
            obj = load_target(p.target)
        except (Exception, SystemExit) as err:  # noqa: BLE001 — a plugin's failure is its own
            problems.append(f"dataset {ds_id!r} ({where}): cannot be imported: {one_line(err)}")
            continue
        fields, problem = _fields(ds_id, p.target, obj)
        if problem:
            problems.append(f"dataset {ds_id!r} ({where}): {problem}")
        else:
            entries.append((ds_id, where, fields))
    return entries, conflicts, problems


def _fields(ds_id: str, target: str, obj) -> tuple[dict, str | None]:
    """The manifest fields of one dataset plugin, or a problem."""
    if isinstance(obj, dict):
        fields = dict(obj)
        if fields.setdefault("id", ds_id) != ds_id:
            return {}, f"its id {fields['id']!r} differs from the entry point's name"
        return fields, None
    if not callable(obj) or inspect.isclass(obj):
        return {}, (
            f"is {describe(obj)}: neither a simulator (a function decorated with replay.sim.generator) "
            "nor a dict of manifest fields"
        )
    if getattr(obj, "PARAMS", None) is None:
        return {}, "declares no parameters (decorate the simulator with replay.sim.generator)"
    problem = declaration_problem(obj.PARAMS)
    if problem:
        return {}, problem
    if target.count(".", target.index(":")):
        return {}, "a simulator's target must be 'module:function'"
    doc = " ".join((inspect.getdoc(obj) or "").split("\n\n")[0].split())
    fields = {
        "id": ds_id,
        "generator": target,
        "site": "simulated",
        "description": str(getattr(obj, "DESCRIPTION", doc)),
        "default_task": str(getattr(obj, "DEFAULT_TASK", "")),
        "license": str(getattr(obj, "LICENSE", "")),
        "citation": str(getattr(obj, "CITATION", "")),
    }
    return fields, None
