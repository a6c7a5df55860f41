"""``replay.score`` from Python (:func:`score`, :class:`ScoreResult`) and the leaderboard rows of
``replay score`` (:func:`leaderboard_row`): one code path, so that the Python call and the
command line give the same numbers.

Inputs are sources as the CLI takes them (a TUM, KITTI, EuRoC or CSV file, ``BAG:topic``,
``BAG:tf:PARENT->CHILD``), :class:`replay.trajectory.Trajectory` objects or pandas DataFrames
(columns ``t, x, y, z`` and optionally ``qx, qy, qz, qw``: :meth:`Trajectory.from_pandas`).
Each estimate is associated, aligned and scored by :func:`replay.trajectory.score` with the
settings of :func:`settings` (those of ``replay score``); its leaderboard row is
:func:`leaderboard_row`, the row ``replay score -o`` writes.
"""
from __future__ import annotations

import json
import math
import os

import numpy as np

from replay.run.pipeline import config_hash
from replay.trajectory import io, row_metrics
from replay.trajectory import score as score_one
from replay.trajectory.base import Trajectory
from replay.trajectory.pose_error import UNITS, statistics
from replay.util.errors import ReplayError


def estimate_name(spec, taken: set) -> str:
    """The name ``replay score`` gives a source (topic, else file stem), made unique in ``taken``."""
    path, topic = io.split(spec)
    return _unique(topic.lstrip("/") if topic else path.stem, taken)


def _unique(base: str, taken: set) -> str:
    name, k = base, 2
    while name in taken:
        name, k = f"{base}#{k}", k + 1
    taken.add(name)
    return name


def settings(*, align: str, n_to_align, align_origin: bool, t_max_diff: float, t_offset: float, relations,
             delta, delta_unit: str, delta_tol: float, all_pairs: bool, pairs_from_reference: bool,
             lengths=None, lengths_method: str = "rpg", **prepare) -> dict:
    """The keyword arguments of :func:`replay.trajectory.score` (and of the configuration hash) for
    the options of ``replay score``; ``delta``: None for no RPE; ``lengths``: the relative errors over
    lengths (``--lengths``), in the settings only when asked for; ``prepare``: evo's trajectory options
    (:data:`PREPARE`: window, sync method, downsampling, motion filter, projection), in the settings
    only where they differ from their defaults (so the hash of a plain call is unchanged)."""
    out = dict(align=align, n_to_align=n_to_align, align_origin=align_origin, t_max_diff=t_max_diff,
               t_offset=t_offset, relations=relations, delta=delta, delta_unit=delta_unit, all_pairs=all_pairs,
               rel_tol=delta_tol, pairs_from_reference=pairs_from_reference)
    if lengths:
        out.update(lengths=lengths, lengths_method=lengths_method)
    if unknown := set(prepare) - set(PREPARE):
        raise TypeError(f"settings: unknown option {sorted(unknown)[0]!r}")
    out.update({k: v for k, v in prepare.items() if v != PREPARE[k]})
    return out


# evo's trajectory options (replay.trajectory.prepare) and their defaults
PREPARE = {"sync_method": "nearest", "t_start": None, "t_end": None, "downsample": None, "motion_filter": None,
           "project_to_plane": None}


def leaderboard_row(s, *, reference: str, dataset: str, estimate: str, name: str, settings: dict,
                    lost_threshold=None, lost_steps: int = 10) -> dict:
    """The leaderboard row (:mod:`replay.scoring.summary` schema) of the score ``s`` of the estimate
    ``estimate`` (its source) named ``name`` against ``reference`` (its source; ``dataset``: its label)."""
    from replay.util.version import __version__

    cfg = {"reference": reference, "estimate": estimate, **settings}
    row = {"dataset": dataset, "task": "trajectory", "filter": f"recorded:{name}", "label": f"recorded:{name}",
           "params": json.dumps({"source": estimate}, sort_keys=True), "runs": 1, "diverged": 0, "failed": 0,
           "seed": "", "first": ""}
    row.update(row_metrics(s, lost_threshold=lost_threshold, lost_steps=lost_steps))
    row.update(us_per_step=math.nan, alignment=settings["align"] + ("+origin" if settings["align_origin"] else ""),
               version=__version__, config_hash=config_hash(cfg))
    return row


class ScoreResult:
    """The scores of one or more estimates against one reference (:func:`score`).

    ``reference`` (the whole reference trajectory), ``scores`` ({name: :class:`replay.trajectory.Score`},
    in the order given), ``rows`` (the leaderboard rows), ``settings``. ``result[name]`` is a Score.
    """

    def __init__(self, reference: Trajectory, scores: dict, rows: list, settings: dict):
        self.reference, self.scores, self.rows, self.settings = reference, scores, rows, settings

    def __getitem__(self, name):
        if name not in self.scores:
            raise ReplayError(f"no estimate named {name!r} (estimates: {', '.join(self.scores)})")
        return self.scores[name]

    def __repr__(self) -> str:
        return (f"<ScoreResult: {', '.join(self.scores)} vs {self.reference.name} "
                f"(align {self.settings['align']}; .stats(), .errors(), .leaderboard(), .plot())>")

    def _repr_html_(self):
        return self.stats()._repr_html_()

    def stats(self):
        """One row per estimate and metric (``ape``/``rpe``) and pose relation: ``estimate``, ``metric``,
        ``relation``, ``unit``, ``n`` (poses or pairs), then ``rmse, mean, median, std, min, max, sse``:
        the numbers ``replay score`` prints, and writes as ``<metric>_<relation>_<stat>``."""
        import pandas as pd

        rows = [{"estimate": name, "metric": kind, "relation": rel, "unit": UNITS[rel], "n": len(e), **statistics(e)}
                for name, s in self.scores.items() for kind, errs in (("ape", s.ape), ("rpe", s.rpe))
                for rel, e in errs.items()]
        df = pd.DataFrame(rows)
        df.attrs["settings"] = dict(self.settings)
        return df

    def errors(self, kind: str = "ape"):
        """Per-pose errors (``kind="ape"``: ``t``, the reference stamp, ``t_estimate``, the
        estimate's as recorded) or per-pair errors (``"rpe"``: ``t_i``, ``t_j``, reference stamps of
        the pair), one column per pose relation (its unit: ``stats()``) and ``err_x, err_y, err_z``
        (APE: aligned estimate minus reference; RPE: the translation error in the reference's frame
        at i; absent for point distances), with an ``estimate`` column; pairs that a relation leaves
        out (point_distance_error_ratio at zero distance) are NaN."""
        import pandas as pd

        if kind not in ("ape", "rpe"):
            raise ReplayError(f"errors: kind must be 'ape' or 'rpe' (got {kind!r:.40})")
        parts = []
        for name, s in self.scores.items():
            if kind == "ape":
                cols = {"t": s.reference.t, "t_estimate": s.estimate.t, **s.ape}
                axes = s.ape_axes
            elif s.rpe_pairs is None:
                continue
            else:
                i, j = s.rpe_pairs
                cols = {"t_i": s.reference.t[i], "t_j": s.reference.t[j]}
                for rel, e in s.rpe.items():
                    if len(e) != len(i):  # only the pairs of non-zero reference distance
                        full = np.full(len(i), np.nan)
                        full[np.linalg.norm(s.reference.p[j] - s.reference.p[i], axis=1) != 0] = e
                        e = full
                    cols[rel] = e
                axes = s.rpe_axes
            if axes is not None:
                cols.update(err_x=axes[:, 0], err_y=axes[:, 1], err_z=axes[:, 2])
            parts.append(pd.DataFrame({"estimate": name, **cols}))
        if not parts:
            raise ReplayError("errors('rpe'): no RPE was computed (give rpe=True or a delta)")
        return pd.concat(parts, ignore_index=True)

    def lengths(self):
        """The relative errors over lengths (``lengths=``): one row per estimate and length, the columns
        ``replay score --lengths -o`` writes (``length``, ``length_m``, ``rel_<error>_<stat>``)."""
        import pandas as pd

        from replay.trajectory import lengths as by_length

        if "lengths" not in self.settings:
            raise ReplayError("lengths(): no lengths were asked for (give lengths='10%,20%,...' or metres)")
        rows = [r for row, s in zip(self.rows, self.scores.values())
                for r in by_length.rows(row, s.lengths, self.settings["lengths_method"])]
        return pd.DataFrame(rows)

    def leaderboard(self):
        """The leaderboard rows as a DataFrame: the columns and values ``replay score -o`` writes
        (every digit kept, as in the CSV; with ``trials=``, each trial and then each set's aggregated row)."""
        import pandas as pd

        from replay.scoring.summary import columns

        rows = _grouped(self.rows)
        return pd.DataFrame(rows, columns=columns(rows))

    def output_rows(self) -> list:
        """The rows ``replay score -o`` writes: each estimate (one row per length with ``lengths``), then each
        trial set's trials and aggregated rows (:func:`replay.run.trials.rows`)."""
        from replay.trajectory import lengths as by_length

        return _grouped([r for row, s in zip(self.rows, self.scores.values())
                         for r in (by_length.rows(row, s.lengths, self.settings["lengths_method"])
                                   if s.lengths else [row])])

    def save(self, path):
        """Write the results archive of ``replay score --save-results`` into the directory ``path``
        (:mod:`replay.run.archive`; read back by ``replay res``); refused onto or inside an input."""
        from replay.run import archive

        archive.check(path, [io.split(spec)[0] for spec in getattr(self, "sources", ())])
        return archive.save(self, path, reference=getattr(self, "reference_spec", None))

    def trials(self):
        """The trial sets (``trials=``): each trial's row and the aggregated row (``trial`` empty: mean over
        trials, ``<m>_median``, ``<m>_ci95``, ``lost``; :mod:`replay.run.trials`), one per length with ``lengths``."""
        import pandas as pd

        from replay.scoring.summary import columns

        rows = [r for r in self.output_rows() if "trial" in r]
        if not rows:
            raise ReplayError("trials(): no trials were scored (give trials={'name': 'runs/est_*.txt'})")
        return pd.DataFrame(rows, columns=columns(rows))

    def plot(self, *, relation: str | None = None, mode: str = "xy", kind: str = "trajectories"):
        """A figure of ``replay score --plot`` (:mod:`replay.trajectory.plot`), the tracks aligned as
        scored, of the pose relation ``relation`` (default: the first) in plot mode ``mode`` (xy, xz, yz,
        xyz): ``kind`` ``trajectories`` (tracks, APE and RPE over time), ``map`` (each track coloured by
        its APE), ``xyz`` (x, y, z over time), ``rpy`` (roll, pitch, yaw over time), or ``all``:
        {kind: Figure} of those that have something to show."""
        from replay.trajectory import plot

        rels = self.settings["relations"]
        if relation is not None and relation not in {r for s in self.scores.values() for r in (*s.ape, *s.rpe)}:
            raise ReplayError(f"plot: relation {relation!r} was not computed (pose_relation: {', '.join(rels)})")
        if kind not in (*plot.KINDS, "all"):
            raise ReplayError(f"plot: kind {kind!r}: expected one of {', '.join(plot.KINDS)}, all")
        figs = plot.figures(self.reference, self.scores, relation=relation, mode=mode,
                            kinds=plot.KINDS if kind == "all" else (kind,))
        if kind == "all":
            return figs
        if kind not in figs:
            raise ReplayError(f"plot: no {kind} figure: " + ("no APE of that relation" if kind == "map" else
                                                              "the reference or the estimates have no orientations"))
        return figs[kind]


def _grouped(rows: list) -> list:
    """``rows`` of plain estimates first, then each trial set's rows and aggregated rows."""
    from replay.run import trials as trial_sets

    plain, sets = [], {}
    for row in rows:
        if row.get("trial", "") == "":
            plain.append(row)
        else:
            sets.setdefault(row["filter"], []).append(row)
    return plain + [r for these in sets.values() for r in trial_sets.rows(these)]


def _trajectory(item, name: str) -> Trajectory:
    import dataclasses

    if isinstance(item, Trajectory):
        return dataclasses.replace(item, name=name)
    return Trajectory.from_pandas(item, name=name)


def _default_name(item, taken: set, k: int) -> str:
    if isinstance(item, (str, os.PathLike)):
        return estimate_name(os.fspath(item), taken)
    own = item.name if isinstance(item, Trajectory) else item.attrs.get("name")
    return _unique(str(own) if own else f"estimate{k}" if k else "reference", taken)


def score(reference, estimates=None, *, align: str = "none", n_to_align=None, align_origin: bool = False,
          t_max_diff: float = 0.01, t_offset: float = 0.0, pose_relation="trans", rpe: bool = False, delta=None,
          delta_unit: str = "f", delta_tol: float = 0.1, all_pairs: bool = False,
          pairs_from_reference: bool = False, fmt=None, kitti_times=None, columns=None, time_unit=None,
          lost_threshold=None, lost_steps: int = 10, names=None, lengths=None, lengths_method: str = "rpg",
          sync_method: str = "nearest", t_start=None, t_end=None, downsample=None, motion_filter=None,
          project_to_plane=None, trials=None) -> ScoreResult:
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
    (``ScoreResult.trials()``, :mod:`replay.run.trials`).
    """
    from replay.run import trials as trial_sets

    sets = trial_sets.parse_api(trials)
    trial_sets.not_reference(sets, reference, "trials")
    if lengths is not None:
        from replay.trajectory import lengths as by_length

        lengths = by_length.parse(lengths if isinstance(lengths, str) else ",".join(f"{v:g}" for v in lengths))
    items = list(estimates) if isinstance(estimates, (list, tuple)) else [] if estimates is None else [estimates]
    if not items and not sets:
        raise ReplayError("score: no estimate (give estimates, or trials=)")
    relations = list(dict.fromkeys([pose_relation] if isinstance(pose_relation, str) else pose_relation))
    want_rpe = rpe or delta is not None or all_pairs
    if "point_distance_error_ratio" in relations and not want_rpe:
        raise ReplayError("pose_relation point_distance_error_ratio is an RPE relation: add rpe=True (or a delta)")
    if names is not None:
        names = [names] if isinstance(names, str) else list(names)
        if len(names) != len(items):
            raise ReplayError(f"names: {len(names)} name{'s' if len(names) != 1 else ''} for {len(items)} "
                              f"estimate{'s' if len(items) != 1 else ''}")
        if twice := [n for n in names if names.count(n) > 1]:
            raise ReplayError(f"names: {twice[0]!r} is given twice")
    taken = set()
    ref_name = _default_name(reference, set(), 0)
    names = names or [_default_name(item, taken, k + 1) for k, item in enumerate(items)]
    members = trial_sets.members(sets)
    items, names = items + [m[3] for m in members], names + [m[0] for m in members]
    sources = [reference, *items]
    specs = [os.fspath(x) if isinstance(x, (str, os.PathLike)) else None for x in sources]
    files = [k for k, spec in enumerate(specs) if spec is not None]
    loaded = dict(zip(files, io.load_all([specs[k] for k in files], names=[([ref_name] + names)[k] for k in files],
                                         fmt=fmt, kitti_times=kitti_times, columns=columns, time_unit=time_unit)))
    ref, *ests = [loaded[k] if k in loaded else _trajectory(x, ([ref_name] + names)[k]) for k, x in enumerate(sources)]
    opts = settings(align=align, n_to_align=n_to_align, align_origin=align_origin, t_max_diff=t_max_diff,
                    t_offset=t_offset, relations=relations, delta=(delta or 1.0) if want_rpe else None,
                    delta_unit=delta_unit, delta_tol=delta_tol, all_pairs=all_pairs,
                    pairs_from_reference=pairs_from_reference, lengths=lengths, lengths_method=lengths_method,
                    sync_method=sync_method, t_start=t_start, t_end=t_end, downsample=downsample,
                    motion_filter=None if motion_filter is None else tuple(motion_filter),
                    project_to_plane=project_to_plane)
    ref_spec = specs[0] or f"<{ref_name}>"
    dataset = io.label(specs[0]) if specs[0] else ref_name
    scores, rows = {}, []
    first_trial = len(names) - len(members)
    for k, (spec, name, est) in enumerate(zip(specs[1:], names, ests)):
        with trial_sets.naming(members[k - first_trial] if k >= first_trial else None):
            s = score_one(ref, est, **opts)
        scores[name] = s
        rows.append(leaderboard_row(s, reference=ref_spec, dataset=dataset, estimate=spec or f"<{name}>", name=name,
                                    settings=opts, lost_threshold=lost_threshold, lost_steps=lost_steps))
    for row, (_, set_name, k, src) in zip(rows[len(rows) - len(members):], members):
        trial_sets.mark(row, set_name, k, src if isinstance(src, (str, os.PathLike)) else f"<{set_name}/{k}>")
    result = ScoreResult(ref, scores, rows, opts)
    result.sources, result.reference_spec = [spec for spec in specs if spec], ref_spec
    return result
