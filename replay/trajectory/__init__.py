"""Trajectories as recorded (files, bags) and their evo-class scoring (APE, RPE).

Modules, bottom up: :mod:`.quat` (quaternion algebra, x y z w), :mod:`.base`
(:class:`Trajectory`, the checks of every reader), :mod:`.files` (TUM, KITTI, EuRoC, CSV),
:mod:`.bag` (bag / MCAP topics and tf), :mod:`.io` (:func:`load` of any source),
:mod:`.associate` (time association), :mod:`.pose_error` (APE, RPE, pairs, statistics),
:mod:`.scoring` (:func:`score`, leaderboard cells), :mod:`.plot` (``replay score --plot``).
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
