"""``replay.score`` from Python (:func:`score`): the options of ``replay score``, sources as paths,
Trajectory objects or DataFrames, the result a :class:`replay.trajectory.score_result.ScoreResult`."""

from __future__ import annotations

import dataclasses
import os

from replay.trajectory.score_result import ScoreResult, estimate_name, leaderboard_row, settings, unique
from replay.trajectory import io
from replay.trajectory import score as score_one
from replay.trajectory.base import Trajectory
from replay.util.errors import ReplayError
from replay.trajectory import trials as trial_sets
from replay.trajectory import lengths as by_length


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
    estimates=None,
    *,
    align: str = "none",
    n_to_align=None,
    align_origin: bool = False,
    t_max_diff: float = 0.01,
    t_offset: float = 0.0,
    pose_relation="trans",
    rpe: bool = False,
    delta=None,
    delta_unit: str = "f",
    delta_tol: float = 0.1,
    all_pairs: bool = False,
    pairs_from_reference: bool = False,
    fmt=None,
    kitti_times=None,
    columns=None,
    time_unit=None,
    lost_threshold=None,
    lost_steps: int = 10,
    names=None,
    lengths=None,
    lengths_method: str = "rpg",
    sync_method: str = "nearest",
    t_start=None,
    t_end=None,
    downsample=None,
    motion_filter=None,
    project_to_plane=None,
    trials=None,
) -> ScoreResult:
    """Score ``estimates`` against ``reference`` as ``replay score`` does: a :class:`ScoreResult`.

    ``reference``, ``estimates`` (one or a list): a trajectory file (TUM, KITTI, EuRoC, CSV),
    ``RECORDING:TOPIC``, ``RECORDING:tf:PARENT->CHILD``, a Trajectory or a DataFrame (``t, x, y, z``
    and optionally ``qx, qy, qz, qw``). The options are the CLI's long options (docs/evo.md):
    ``align`` none, yaw, se3 (evo's ``-a``), sim3 (``-as``) or scale (``-s``); ``pose_relation``
    (``-r``, one or a list); ``rpe``, ``delta``, ``delta_unit``, ``delta_tol``, ``all_pairs``,
    ``pairs_from_reference`` (the RPE); ``fmt``, ``kitti_times``, ``columns``, ``time_unit`` (files);
    ``names``: one per estimate (default: the topic, else the file stem, else the trajectory's name);
    ``lengths`` (``"10%,20%"`` or a list of those strings), ``lengths_method``: the relative errors over
    lengths (``ScoreResult.lengths()``); evo's trajectory options ``sync_method``, ``t_start``, ``t_end``,
    ``downsample``, ``motion_filter`` ((metres, degrees)), ``project_to_plane`` (:mod:`replay.trajectory.prepare`);
    ``trials``: trials of one estimator each, ``{name: glob or [sources]}`` (or one glob, or a list of
    ``NAME=GLOB``; ``estimates`` may then be empty), scored as ``NAME/1``.. and aggregated
    (``ScoreResult.trials()``, :mod:`replay.trajectory.trials`).
    """

    sets = trial_sets.parse_api(trials)
    trial_sets.not_reference(sets, reference, "trials")
    if lengths is not None:
        lengths = by_length.parse(lengths if isinstance(lengths, str) else ",".join(f"{v:g}" for v in lengths))
    items = list(estimates) if isinstance(estimates, (list, tuple)) else [] if estimates is None else [estimates]
    if not items and not sets:
        raise ReplayError("score: no estimate (give estimates, or trials=)")
    relations = list(dict.fromkeys([pose_relation] if isinstance(pose_relation, str) else pose_relation))
    want_rpe = rpe or delta is not None or all_pairs
    if "point_distance_error_ratio" in relations and not want_rpe:
        raise ReplayError("pose_relation point_distance_error_ratio is an RPE relation: add rpe=True (or a delta)")
    names = _names(items, names)
    members = trial_sets.members(sets)
    items, names = items + [m[3] for m in members], names + [m[0] for m in members]
    specs, ref, ests = _load(
        reference, items, names, fmt=fmt, kitti_times=kitti_times, columns=columns, time_unit=time_unit
    )
    opts = settings(
        align=align,
        n_to_align=n_to_align,
        align_origin=align_origin,
        t_max_diff=t_max_diff,
        t_offset=t_offset,
        relations=relations,
        delta=(delta or 1.0) if want_rpe else None,
        delta_unit=delta_unit,
        delta_tol=delta_tol,
        all_pairs=all_pairs,
        pairs_from_reference=pairs_from_reference,
        lengths=lengths,
        lengths_method=lengths_method,
        sync_method=sync_method,
        t_start=t_start,
        t_end=t_end,
        downsample=downsample,
        motion_filter=None if motion_filter is None else tuple(motion_filter),
        project_to_plane=project_to_plane,
    )
    return _scored(ref, ests, specs, names, members, opts, lost_threshold=lost_threshold, lost_steps=lost_steps)


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


def _scored(ref, ests, specs, names, members, opts, *, lost_threshold, lost_steps) -> ScoreResult:
    """Each estimate scored (trials marked as such) into a :class:`ScoreResult`."""

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
                lost_threshold=lost_threshold,
                lost_steps=lost_steps,
            )
        )
    for row, (_, set_name, k, src) in zip(rows[len(rows) - len(members) :], members):
        trial_sets.mark(row, set_name, k, src if isinstance(src, (str, os.PathLike)) else f"<{set_name}/{k}>")
    result = ScoreResult(ref, scores, rows, opts)
    result.sources, result.reference_spec = [spec for spec in specs if spec], ref_spec
    return result
