"""Everything ``replay tune`` is given, checked before any trial (one line each, ReplayError)."""

from __future__ import annotations

from replay.data import dataset_ref, registry
from replay.filters import make_filter
from replay.run.eval_options import DEFAULTS
from replay.run.pipeline import build_problem, default_task, plain
from replay.scoring import likelihood
from replay.tasks import make_task
from replay.util.errors import ReplayError

from . import objectives, space, splits
from .options import TuneOptions
from .run import Tune


def prepare(o: TuneOptions) -> Tune:
    """The checked :class:`Tune` of the options ``o`` (no trial run, no file written)."""
    registry.check_data_dir(o.data_dir)
    filters, seed, first, data_dir, task = o.filters, o.seed, o.first, o.data_dir, o.task
    names = [f.strip() for f in filters if f.strip()]
    if not names:
        raise ReplayError("--filters: no filter named")
    for n in names:
        if n == "measurements" or n.startswith("recorded:"):
            raise ReplayError(f"--filters {n}: nothing to tune (no filter parameters)")
        make_filter(n)  # unknown: one line naming the known ones
    if len(set(names)) < len(names):
        raise ReplayError(f"--filters {','.join(names)}: a filter named twice")
    weights = objectives.parse(o.objective)
    view = {k: v for k, v in (o.view or {}).items() if v is not None}
    s = splits.make(
        o.dataset,
        {**(o.dataset_params or {}), **view},
        train_segment=o.train_segment,
        train=o.train,
        test=o.test,
        split=o.split,
        seed=seed,
    )
    refs = {d: dataset_ref.resolve(d) for d, _ in s.train + s.test}  # each id parsed once
    checked = [(d, plain(registry.check_params(refs[d].target, p))) for d, p in s.train + s.test]  # canonical
    s.train, s.test = checked[: len(s.train)], checked[len(s.train) :]
    splits.check_parts(s, seed=seed, first=first, data_dir=data_dir, refs=refs, allow_overlap=o.allow_overlap)
    first_ds, first_p = s.train[0]
    task = task or default_task(refs[first_ds], first=first, data_dir=data_dir, dataset_params=first_p, seed=seed)
    make_task(task, **(o.task_params or {}))
    dims = space.build(o.entries, names, task)
    t = Tune(
        task,
        names,
        dims,
        o.trials,
        o.objective,
        weights,
        s,
        o.runs,
        seed,
        dict(o.task_params or {}),
        first,
        o.alignment,
        data_dir,
        o.batch or DEFAULTS["batch"],
    )
    if "nll" in weights:
        _check_nll(t)
    return t


def _check_nll(t: Tune) -> None:
    """The likelihood objective only where the runs record it (:mod:`replay.scoring.likelihood`)."""
    for name in t.filters:
        why = likelihood.provides(name)
        if why is not None:
            raise ReplayError(
                f"--objective {t.objective}: filter {name!r} cannot provide the innovations' likelihood ({why})"
            )
    problem = build_problem(t.configs("train", t.filters[0], {})[0], 0, t.data_dir)
    if likelihood.linear_matrices(problem.model) is None:
        raise ReplayError(
            f"--objective {t.objective}: task {t.task!r} has a nonlinear model "
            f"({type(problem.model).__name__}); the likelihood is computed on linear models only"
        )
