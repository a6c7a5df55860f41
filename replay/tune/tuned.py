"""``replay eval --tuned FILE``: the filter (and task) parameters of a ``tuned.toml``.

The file is a campaign file (:mod:`replay.campaign.spec`, checked as such); ``replay eval``
takes from it the filters and their parameters, and the task's parameters, so that
``replay eval DATASET --tuned DIR/tuned.toml --runs R --seed S`` (with the views of the
test data) gives the rows ``replay tune`` scored on its held-out data.
"""

from __future__ import annotations

from replay.util.errors import ReplayError


def tuned_params(path, task: str | None = None, allow_modules=()) -> tuple[list, dict, dict, str]:
    """(filters, {filter: params}, task params, task) of a tuned file; a ``module:Class`` filter or
    task of a module not in ``allow_modules`` is refused before anything is imported."""
    from replay.campaign import spec

    camp = spec.load(path, allow_modules, reader="--tuned")
    cfgs = [c for c in camp.configs if task is None or c.task == task]
    if not cfgs:
        raise ReplayError(f"--tuned {path}: no configuration of task {task!r} in it")
    tasks = {c.task for c in cfgs}
    if len(tasks) > 1:
        raise ReplayError(f"--tuned {path}: configurations of several tasks ({', '.join(sorted(tasks))}); give --task")
    filters, fparams, tparams = [], {}, None
    for c in cfgs:
        if c.filter in fparams and fparams[c.filter] != c.filter_params:
            raise ReplayError(f"--tuned {path}: filter {c.filter!r} has two parameter sets; one per filter")
        if tparams is not None and tparams != c.task_params:
            raise ReplayError(f"--tuned {path}: two sets of task parameters; one per file")
        if c.filter not in fparams:
            filters.append(c.filter)
        fparams[c.filter], tparams = dict(c.filter_params), dict(c.task_params)
    return filters, fparams, tparams or {}, tasks.pop()
