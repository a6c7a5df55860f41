"""``replay.score`` from Python (:func:`score`): the options of ``replay score``, sources as paths,
Trajectory objects or DataFrames, the result a :class:`replay.trajectory.score_result.ScoreResult`."""

from __future__ import annotations

import dataclasses
import os

from replay.trajectory.score_options import ScoreOptions
from replay.trajectory.score_result import ScoreResult, estimate_name, leaderboard_row, unique
from replay.trajectory import io
from replay.trajectory import score as score_one
from replay.trajectory.base import Trajectory
from replay.util.errors import ReplayError
from replay.trajectory import trials as trial_sets


def _trajectory(item, name: str) -> Trajectory:

    if isinstance(item, Trajectory):
        return dataclasses.replace(item, name=name)
    return Trajectory.from_pandas(item, name=name)


def _default_name(item, taken: set, k: int) -> str:
    if isinstance(item, (str, os.PathLike)):
        return estimate_name(os.fspath(item), taken)
    own = item.name if isinstance(item, Trajectory) else item.attrs.get("name")
    return unique(str(own) if own else f"estimate{k}" if k else "reference", taken)


def score(
    reference,
    estimates,
    options: ScoreOptions,
    *,
    names=None,
    trials=None,
    fmt=None,
    kitti_times=None,
    columns=None,
    time_unit=None,
) -> ScoreResult:
    """Score ``estimates`` against ``reference`` as ``replay score`` does, with ``options`` (the record the
    API builds from ``replay.score``'s keywords, :func:`replay.api.score`): a :class:`ScoreResult`.

    ``reference``, ``estimates`` (one or a list): a trajectory file (TUM, KITTI, EuRoC, CSV),
    ``RECORDING:TOPIC``, ``RECORDING:tf:PARENT->CHILD``, a Trajectory or a DataFrame (``t, x, y, z``
    and optionally ``qx, qy, qz, qw``); ``fmt``, ``kitti_times``, ``columns``, ``time_unit``: how files
    are read; ``names``: one per estimate (default: the topic, else the file stem, else the trajectory's
    name); ``trials``: trials of one estimator each, ``{name: glob or [sources]}`` (or one glob, or a
    list of ``NAME=GLOB``; ``estimates`` may then be empty), scored as ``NAME/1``.. and aggregated
    (``ScoreResult.trials()``, :mod:`replay.trajectory.trials`).
    """
    sets = trial_sets.parse_api(trials)
    trial_sets.not_reference(sets, reference, "trials")
    items = list(estimates) if isinstance(estimates, (list, tuple)) else [] if estimates is None else [estimates]
    if not items and not sets:
        raise ReplayError("score: no estimate (give estimates, or trials=)")
    names = _names(items, names)
    members = trial_sets.members(sets)
    items, names = items + [m[3] for m in members], names + [m[0] for m in members]
    specs, ref, ests = _load(
        reference, items, names, fmt=fmt, kitti_times=kitti_times, columns=columns, time_unit=time_unit
    )
    return _scored(ref, ests, specs, names, members, options)


def _names(items: list, names) -> list:
    """One name per estimate: ``names`` checked, else the topic, the file stem or the trajectory's name."""
    if names is not None:
        names = [names] if isinstance(names, str) else list(names)
        if len(names) != len(items):
            raise ReplayError(
                f"names: {len(names)} name{'s' if len(names) != 1 else ''} for {len(items)} "
                f"estimate{'s' if len(items) != 1 else ''}"
            )
        if twice := [n for n in names if names.count(n) > 1]:
            raise ReplayError(f"names: {twice[0]!r} is given twice")
        return names
    taken = set()
    return [_default_name(item, taken, k + 1) for k, item in enumerate(items)]


def _load(reference, items: list, names: list, **file_options) -> tuple:
    """(the sources' paths or None, the reference, the estimates): files and recordings read (each
    recording once), Trajectory objects and DataFrames taken as they are."""
    ref_name = _default_name(reference, set(), 0)
    sources, labels = [reference, *items], [ref_name, *names]
    specs = [os.fspath(x) if isinstance(x, (str, os.PathLike)) else None for x in sources]
    files = [k for k, spec in enumerate(specs) if spec is not None]
    read = io.load_all([specs[k] for k in files], names=[labels[k] for k in files], **file_options)
    loaded = dict(zip(files, read))
    ref, *ests = [loaded[k] if k in loaded else _trajectory(x, labels[k]) for k, x in enumerate(sources)]
    return specs, ref, ests


def _scored(ref, ests, specs, names, members, options: ScoreOptions) -> ScoreResult:
    """Each estimate scored (trials marked as such) into a :class:`ScoreResult`."""
    opts = options.settings()
    ref_spec = specs[0] or f"<{ref.name}>"
    dataset = io.label(specs[0]) if specs[0] else ref.name
    scores, rows = {}, []
    first_trial = len(names) - len(members)
    for k, (spec, name, est) in enumerate(zip(specs[1:], names, ests)):
        with trial_sets.naming(members[k - first_trial] if k >= first_trial else None):
            s = score_one(ref, est, **opts)
        scores[name] = s
        rows.append(
            leaderboard_row(
                s,
                reference=ref_spec,
                dataset=dataset,
                estimate=spec or f"<{name}>",
                name=name,
                settings=opts,
                lost_threshold=options.lost_threshold,
                lost_steps=options.lost_steps,
            )
        )
    for row, (_, set_name, k, src) in zip(rows[len(rows) - len(members) :], members):
        trial_sets.mark(row, set_name, k, src if isinstance(src, (str, os.PathLike)) else f"<{set_name}/{k}>")
    result = ScoreResult(ref, scores, rows, opts)
    result.sources, result.reference_spec = [spec for spec in specs if spec], ref_spec
    return result
