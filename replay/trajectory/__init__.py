"""Trajectories as recorded (files, bags) and their evo-class scoring (APE, RPE): the product of
``replay score|res|convert``, all of it here (``replay/run/`` only runs filters).

Modules, bottom up: :mod:`.quat` (quaternion algebra, x y z w), :mod:`.base`
(:class:`Trajectory`, the checks of every reader), :mod:`.files` (TUM, KITTI, EuRoC, CSV),
:mod:`.bag` (bag / MCAP topics and tf), :mod:`.io` (:func:`load` of any source),
:mod:`.associate` (time association), :mod:`.pose_error` (APE, RPE, pairs, statistics),
:mod:`.scoring` (:func:`score`, leaderboard cells), :mod:`.plot` (``replay score --plot``).
On top, the product: :mod:`.score_api` (``replay.score``, many estimates and trial sets),
:mod:`.score_result` (its result: rows, tables, saved files), :mod:`.trials` (trial sets
aggregated), :mod:`.archive` (``--save-results`` directories), :mod:`.res` (``replay res``),
:mod:`.boxplots`, :mod:`.convert` (``replay convert``). A configuration's hash is
:mod:`replay.util.canonical`'s, shared with the pipeline.
Alignment is :mod:`replay.scoring.align`, shared with the ATE column of the filters' leaderboard.
The library never imports evo; evo is the test oracle (``tests/test_trajectory_evo.py``).
"""

from replay.trajectory.associate import associate
from replay.trajectory.base import Trajectory, make
from replay.trajectory.io import load
from replay.trajectory.pose_error import ape, pairs, rpe, statistics
from replay.trajectory.scoring import Score, row_metrics, score

__all__ = [
    "Score",
    "Trajectory",
    "ape",
    "associate",
    "load",
    "make",
    "pairs",
    "row_metrics",
    "rpe",
    "score",
    "statistics",
]
