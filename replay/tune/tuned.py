"""``replay eval --tuned FILE``: the filter (and task) parameters of a ``tuned.toml``.

The file is a campaign file (:mod:`replay.campaign.spec`, checked as such); ``replay eval``
takes from it the filters and their parameters, and the task's parameters, so that
``replay eval DATASET --tuned DIR/tuned.toml --runs R --seed S`` (with the views of the
test data) gives the rows ``replay tune`` scored on its held-out data.
"""

from __future__ import annotations

from dataclasses import replace

from replay.util.errors import ReplayError
from replay.campaign import spec
from replay.data import dataset_ref, registry
from replay.run.eval_options import EvalOptions
from replay.run.pipeline import plain
from replay.data import views


def tuned_params(path, task: str | None = None, allow_modules=()) -> tuple[list, dict, dict, str]:
    """(filters, {filter: params}, task params, task) of a tuned file; a ``module:Class`` filter or
    task of a module not in ``allow_modules`` is refused before anything is imported."""

    try:
        camp = spec.load(path, allow_modules, reader="--tuned")
    except ReplayError as e:  # the file named: as the user gave it
        raise ReplayError(f"--tuned {e}") from None
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


RUN_OPTIONS = ("runs", "seed", "alignment", "divergence_threshold")  # of the file's [campaign] table


def with_tuned(path, dataset, options: EvalOptions, given=frozenset(), allow_modules=()) -> tuple[EvalOptions, str]:
    """``replay eval DATASET --tuned FILE``'s options: ``options`` (those of the command line) with the
    file's filters (unless ``"filters"`` is in ``given``, the names of the options given on the command
    line), its filter and task parameters (the given ones win) and, on the data the tune tested on
    (:func:`tuned_data`), its test data and its run options not given; and a note or None."""
    o = options
    names, t_fparams, t_tparams, task = tuned_params(path, o.task, allow_modules)
    names = list(o.filters) if "filters" in given else names
    fparams = o.filter_params or {}
    fparams = {n: {**t_fparams.get(n, {}), **fparams.get(n, {})} for n in names if n in t_fparams or n in fparams}
    ref = dataset_ref.resolve(dataset, o.adapter)
    run = {k: getattr(o, k) for k in RUN_OPTIONS}
    dparams, first, run, note = tuned_data(path, ref, o.dataset_params or {}, o.first, run, set(given))
    tparams = {**t_tparams, **(o.task_params or {})}
    merged = dict(task=task, filters=names, filter_params=fparams, task_params=tparams, first=first, **run)
    return replace(o, dataset_params=dparams or None, **merged), note


def tuned_data(path, ref, dataset_params: dict, first, run: dict, given: set) -> tuple[dict, object, dict, str | None]:
    """The data the tune tested on, for ``replay eval DATASET --tuned FILE``: (dataset parameters,
    ``first``, run options, a note or None).

    When the file holds ``DATASET`` (its test data), its dataset parameters (the views ``rate``,
    ``window``, ``segment`` and the generator's or adapter's own), its ``first``, and the run
    options of its ``[campaign]`` table not given on the command line (``given``: ``runs``,
    ``seed``, ...) are applied, so that the command gives the tune's held-out rows; a dataset
    parameter or ``--first`` of the command line that differs from the file is refused in one
    line; but for injected faults (``fault``, :mod:`replay.data.faults`) on a tune made without them:
    the tuned configuration stressed on its own test data. Another dataset takes the file's filter
    and task parameters only, with a note saying so.
    """

    camp = spec.load(path)
    same = [c for c in camp.configs if c.dataset in (ref.id, str(ref.path.resolve()) if ref.path else None)]
    if not same:
        tested = ", ".join(sorted({_describe(c.dataset, c.dataset_params) for c in camp.configs}))
        note = (
            f"--tuned {path}: tested on {tested}; {ref.id} is evaluated as given (only its filter and task parameters)"
        )
        return dataset_params, first, run, note
    c = same[0]
    mine = plain(registry.check_params(ref.target, dataset_params, adapter=ref.adapter if ref.is_path else None))
    stress = "fault" in dataset_params and "fault" not in c.dataset_params  # the clean tune under faults
    for k in dataset_params:
        if mine.get(k) != c.dataset_params.get(k) and not (k == "fault" and stress):
            recorded = f"{k}={c.dataset_params[k]}" if k in c.dataset_params else f"no {k}"
            raise ReplayError(
                f"--tuned {path}: the tune tested on {recorded} for {ref.id}, the command line gives "
                f"{k}={dataset_params[k]}; leave it out to evaluate on the tune's test data"
            )
    if first is not None and first != c.first:
        raise ReplayError(
            f"--tuned {path}: the tune tested on first={c.first} for {ref.id}, the command line gives "
            f"--first {first}; leave it out"
        )
    run = {**run, **{k: getattr(c, k) if k != "runs" else camp.runs for k in RUN_OPTIONS if k not in given}}
    return dict(c.dataset_params, **({"fault": mine["fault"]} if stress else {})), c.first, run, None


def _describe(dataset: str, params: dict) -> str:

    shown = views.split(params)[0]
    return dataset + (" (" + ", ".join(f"{k}={v}" for k, v in shown.items()) + ")" if shown else "")
