"""The result of ``replay.score`` (:class:`ScoreResult`; the call: :func:`replay.trajectory.score_api.score`)
and the leaderboard rows of ``replay score`` (:func:`leaderboard_row`): one code path, so that the
Python call and the command line give the same numbers.

Inputs are sources as the CLI takes them (a TUM, KITTI, EuRoC or CSV file, ``BAG:topic``,
``BAG:tf:PARENT->CHILD``), :class:`replay.trajectory.Trajectory` objects or pandas DataFrames
(columns ``t, x, y, z`` and optionally ``qx, qy, qz, qw``: :meth:`Trajectory.from_pandas`).
Each estimate is associated, aligned and scored by :func:`replay.trajectory.score` with the
settings of :meth:`replay.trajectory.score_options.ScoreOptions.settings` (those of ``replay score``);
its leaderboard row is :func:`leaderboard_row`, the row ``replay score -o`` writes.
"""

from __future__ import annotations

import json
import math

import numpy as np

from replay.util.canonical import config_hash
from replay.trajectory import io, row_metrics, plot
from replay.trajectory.base import Trajectory
from replay.trajectory.pose_error import UNITS, statistics
from replay.util.errors import ReplayError
from replay.util.version import __version__
from replay.trajectory import lengths as by_length
from replay.scoring.summary import columns
from replay.trajectory import archive
from replay.trajectory import trials as trial_sets

# pandas (1.5 s to import, measured with `python -X importtime` on the 2-core machine under load) and
# matplotlib (1.3 s) are imported inside the functions that need them: `replay score` without tables,
# archives or plots, and every other command, load neither.


def estimate_name(spec, taken: set) -> str:
    """The name ``replay score`` gives a source (topic, else file stem), made unique in ``taken``."""
    path, topic = io.split(spec)
    return unique(topic.lstrip("/") if topic else path.stem, taken)


def unique(base: str, taken: set) -> str:
    name, k = base, 2
    while name in taken:
        name, k = f"{base}#{k}", k + 1
    taken.add(name)
    return name


def leaderboard_row(
    s,
    *,
    reference: str,
    dataset: str,
    estimate: str,
    name: str,
    settings: dict,
    lost_threshold=None,
    lost_steps: int = 10,
) -> dict:
    """The leaderboard row (:mod:`replay.scoring.summary` schema) of the score ``s`` of the estimate
    ``estimate`` (its source) named ``name`` against ``reference`` (its source; ``dataset``: its label)."""

    cfg = {"reference": reference, "estimate": estimate, **settings}
    row = {
        "dataset": dataset,
        "task": "trajectory",
        "filter": f"recorded:{name}",
        "label": f"recorded:{name}",
        "params": json.dumps({"source": estimate}, sort_keys=True),
        "runs": 1,
        "diverged": 0,
        "failed": 0,
        "seed": "",
        "first": "",
    }
    row.update(row_metrics(s, lost_threshold=lost_threshold, lost_steps=lost_steps))
    row.update(
        us_per_step=math.nan,
        alignment=settings["align"] + ("+origin" if settings["align_origin"] else ""),
        version=__version__,
        config_hash=config_hash(cfg),
    )
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
        return (
            f"<ScoreResult: {', '.join(self.scores)} vs {self.reference.name} "
            f"(align {self.settings['align']}; .stats(), .errors(), .leaderboard(), .plot())>"
        )

    def _repr_html_(self):
        return self.stats()._repr_html_()

    def stats(self):
        """One row per estimate and metric (``ape``/``rpe``) and pose relation: ``estimate``, ``metric``,
        ``relation``, ``unit``, ``n`` (poses or pairs), then ``rmse, mean, median, std, min, max, sse``:
        the numbers ``replay score`` prints, and writes as ``<metric>_<relation>_<stat>``."""
        # lazy: start-up, pandas measured ~740 ms: `replay score` imports this module, pandas only for tables
        import pandas as pd  # noqa: PLC0415

        rows = [
            {"estimate": name, "metric": kind, "relation": rel, "unit": UNITS[rel], "n": len(e), **statistics(e)}
            for name, s in self.scores.items()
            for kind, errs in (("ape", s.ape), ("rpe", s.rpe))
            for rel, e in errs.items()
        ]
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
        # lazy: start-up, pandas measured ~740 ms: `replay score` imports this module, pandas only for tables
        import pandas as pd  # noqa: PLC0415

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
        # lazy: start-up, pandas measured ~740 ms: `replay score` imports this module, pandas only for tables
        import pandas as pd  # noqa: PLC0415

        if "lengths" not in self.settings:
            raise ReplayError("lengths(): no lengths were asked for (give lengths='10%,20%,...' or metres)")
        rows = [
            r
            for row, s in zip(self.rows, self.scores.values())
            for r in by_length.rows(row, s.lengths, self.settings["lengths_method"])
        ]
        return pd.DataFrame(rows)

    def leaderboard(self):
        """The leaderboard rows as a DataFrame: the columns and values ``replay score -o`` writes
        (every digit kept, as in the CSV; with ``trials=``, each trial and then each set's aggregated row)."""
        # lazy: start-up, pandas measured ~740 ms: `replay score` imports this module, pandas only for tables
        import pandas as pd  # noqa: PLC0415

        rows = _grouped(self.rows)
        return pd.DataFrame(rows, columns=columns(rows))

    def output_rows(self) -> list:
        """The rows ``replay score -o`` writes: each estimate (one row per length with ``lengths``), then each
        trial set's trials and aggregated rows (:func:`replay.trajectory.trials.rows`)."""

        return _grouped(
            [
                r
                for row, s in zip(self.rows, self.scores.values())
                for r in (by_length.rows(row, s.lengths, self.settings["lengths_method"]) if s.lengths else [row])
            ]
        )

    def save(self, path):
        """Write the results archive of ``replay score --save-results`` into the directory ``path``
        (:mod:`replay.trajectory.archive`; read back by ``replay res``); refused onto or inside an input."""

        archive.check(path, [io.split(spec)[0] for spec in getattr(self, "sources", ())])
        return archive.save(self, path, reference=getattr(self, "reference_spec", None))

    def trials(self):
        """The trial sets (``trials=``): each trial's row and the aggregated row (``trial`` empty: mean over
        trials, ``<m>_median``, ``<m>_ci95``, ``lost``; :mod:`replay.trajectory.trials`), one per length
        with ``lengths``."""
        # lazy: start-up, pandas measured ~740 ms: `replay score` imports this module, pandas only for tables
        import pandas as pd  # noqa: PLC0415

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
        rels = self.settings["relations"]
        if relation is not None and relation not in {r for s in self.scores.values() for r in (*s.ape, *s.rpe)}:
            raise ReplayError(f"plot: relation {relation!r} was not computed (pose_relation: {', '.join(rels)})")
        if kind not in (*plot.KINDS, "all"):
            raise ReplayError(f"plot: kind {kind!r}: expected one of {', '.join(plot.KINDS)}, all")
        figs = plot.figures(
            self.reference, self.scores, relation=relation, mode=mode, kinds=plot.KINDS if kind == "all" else (kind,)
        )
        if kind == "all":
            return figs
        if kind not in figs:
            raise ReplayError(
                f"plot: no {kind} figure: "
                + (
                    "no APE of that relation"
                    if kind == "map"
                    else "the reference or the estimates have no orientations"
                )
            )
        return figs[kind]


def _grouped(rows: list) -> list:
    """``rows`` of plain estimates first, then each trial set's rows and aggregated rows."""

    plain, sets = [], {}
    for row in rows:
        if row.get("trial", "") == "":
            plain.append(row)
        else:
            sets.setdefault(row["filter"], []).append(row)
    return plain + [r for these in sets.values() for r in trial_sets.rows(these)]
