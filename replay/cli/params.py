"""Parameters given on the command line: parsed, then checked against the declarations.

``-p FILTER.NAME=VALUE``, ``--task-param NAME=VALUE`` and ``--dataset-param
NAME=VALUE``: the value is read as JSON (``500``, ``1.5``, ``true``, ``null``,
``[1, 2]``, ``NaN``), and a bare word that is not JSON stays a string
(``resampling=systematic``). Everything is refused with one line naming the
option, the parameter, what it accepts and the value given:

* :func:`filter_params`: a missing ``FILTER.`` prefix, an unknown filter, a
  filter not among ``--filters`` (with the registered name suggested), an
  unknown parameter, a value its declaration refuses;
* :func:`task_params`, :func:`dataset_params`: the same against the task's
  and the dataset's declarations when they are known;
* :func:`replay.run.checks.check_config` (called by :func:`replay.outputs.eval_job.run_eval`):
  the whole configuration at once, before any data is read, every parameter made canonical.

Recorded estimates (``[estimates]`` of a bag mapping) are named in ``--filters``
as ``recorded:<name>`` (:func:`split_filters`) and take ``-p
recorded:<name>.t_max_diff=...`` / ``t_offset`` (:data:`replay.trajectory.recorded.RECORDED_PARAMS`).
"""

from __future__ import annotations

import difflib
import json
from replay.util.errors import ReplayError, shown


def parse(item: str, option: str) -> tuple[str, object]:
    """``"NAME=VALUE"`` -> ``("NAME", value)``, the value read as JSON (a bare word stays a string)."""
    key, sep, text = item.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ReplayError(f"{option} {shown(item)}: expected NAME=VALUE")
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        value = text
    return key, value


def _assignments(items, option: str) -> dict:
    out: dict = {}
    for item in items:
        key, value = parse(item, option)
        if key in out:
            raise ReplayError(f"{option} {key}: given twice ({_text(out[key])} and {_text(value)})")
        out[key] = value
    return out


def _text(value) -> str:
    return json.dumps(value) if not isinstance(value, str) else value


def _suggest(name: str, known) -> str:
    near = difflib.get_close_matches(name.replace("_", "-"), list(known), n=1, cutoff=0.6)
    return f" (did you mean {near[0]}?)" if near else ""


def split_filters(names) -> tuple[list, list | None]:
    """``--filters`` items -> (offline filters, recorded estimates to score).

    ``none`` alone: no offline filter. ``recorded:<name>`` items choose the recorded
    estimates (``recorded:none``: none of them); without any, every estimate the
    mapping declares is scored (``None``).
    """
    from replay.trajectory.recorded import RECORDED, is_recorded

    names = list(names)
    if not names:
        raise ReplayError("--filters: no filter named")
    offline = [n for n in names if not is_recorded(n)]
    chosen = [n for n in names if is_recorded(n)]
    if "none" in offline:
        if offline != ["none"]:
            raise ReplayError(
                f"--filters: 'none' (no offline filter) cannot be listed with filters "
                f"({', '.join(n for n in offline if n != 'none')})"
            )
        offline = []
    for n in chosen:
        if n == RECORDED or (n == f"{RECORDED}none" and len(chosen) > 1):
            raise ReplayError(
                f"--filters {shown(n)}: expected recorded:<name> (an [estimates] name of the mapping) "
                "or recorded:none alone"
            )
    if len(set(names)) != len(names):
        raise ReplayError(f"--filters: a name is listed twice ({', '.join(names)})")
    recorded = None if not chosen else [] if chosen == [f"{RECORDED}none"] else chosen
    return offline, recorded


def filter_params(items, filters) -> dict:
    """``["pf.n_particles=500", ...]`` -> ``{"pf": {"n_particles": 500}}``, checked against the
    declarations of the filters named in ``filters`` (the ``--filters`` list)."""
    from replay.filters import FILTERS

    filters = list(filters)
    out: dict = {}
    for item in items:
        key, value = parse(item, "-p")
        name, dot, param = key.rpartition(".") if ":" in key else key.partition(".")  # recorded:NAME, module:Class
        if not dot or not name or not param:
            raise ReplayError(
                f"-p {item}: expected FILTER.NAME=VALUE, e.g. {(filters or ['pf'])[0]}.{param or key}={_text(value)}"
            )
        if name.startswith("recorded:"):  # a recorded estimate: its association parameters
            from replay.trajectory.recorded import RECORDED_PARAMS

            if any(f.startswith("recorded:") for f in filters) and name not in filters:
                raise ReplayError(f"-p {item}: {shown(name)} is not in --filters ({', '.join(filters)})")
            given = out.setdefault(name, {})
            if param in given:
                raise ReplayError(f"-p {name}.{param}: given twice ({_text(given[param])} and {_text(value)})")
            given[param] = check_one(RECORDED_PARAMS, param, value, f"recorded estimate {shown(name[9:])}")
            continue
        if name not in FILTERS:
            raise ReplayError(
                f"-p {item}: unknown filter {shown(name)}{_suggest(name, FILTERS)} "
                f"(known: {', '.join(sorted(FILTERS))})"
            )
        if name not in filters:
            raise ReplayError(f"-p {item}: filter {shown(name)} is not in --filters ({', '.join(filters)})")
        given = out.setdefault(name, {})
        if param in given:
            raise ReplayError(f"-p {name}.{param}: given twice ({_text(given[param])} and {_text(value)})")
        given[param] = check_one(filter_declarations(name), param, value, f"filter {shown(name)}")
    return out


def task_params(items, task: str | None = None) -> dict:
    """``["r=2", ...]`` -> ``{"r": 2.0}``; checked against ``task``'s declarations when it is given."""
    from replay.tasks import task_class

    given = _assignments(items, "--task-param")
    if task is None:
        return given
    cls = task_class(task)
    return {k: check_one(cls.PARAMS, k, v, cls.owner()) for k, v in given.items()}


def dataset_params(items, dataset=None, adapter: str | None = None, option: str = "--dataset-param") -> dict:
    """``["q=10", ...]`` -> ``{"q": 10.0}``; checked against ``dataset``'s declarations (a
    simulator's parameters, or its adapter's options) when it is given. Only the given ones."""
    from replay.data import registry

    given = _assignments(items, option)
    if dataset is None:
        return given
    full = registry.check_params(dataset, given, adapter=adapter)
    return {k: full[k] for k in given}


def dataset_inputs(items, mapping=None) -> dict:
    """The dataset parameters of ``replay eval`` and ``replay datasets info``: ``--dataset-param``
    assignments, plus ``--mapping`` (a bag's or MCAP's topic mapping) as its absolute path."""
    from pathlib import Path

    given = dataset_params(items)
    if mapping:
        given["mapping"] = str(Path(mapping).resolve())
    return given


def check_one(declarations, name: str, value, owner: str):
    """One value checked (and normalised) by the declaration of ``name``."""
    from replay.util.params import validate

    return validate(declarations, {name: value}, owner)[name]


def filter_declarations(name: str):
    """The declared parameters of filter ``name``."""
    from replay.filters import FILTERS
    from replay.util.lookup import resolve

    return resolve(FILTERS, name, "filter").PARAMS
