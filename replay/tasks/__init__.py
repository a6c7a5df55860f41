"""Tasks: what is measured over a frame, by which model.

A task turns a :class:`replay.frame.Frame` into a :class:`Problem`: the model,
the measurement array the filters see, the prior, and — kept for the scorer
only — the truth. ``TASKS`` maps task names to "module:Class". Every task
declares its parameters (``PARAMS``, :mod:`replay.util.params`): they are
checked strictly when the task is made, before any data is read.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from replay.util.params import Declared, Param

TASKS = {
    "position": "replay.tasks.position:PositionTask",
    "sonar": "replay.tasks.sonar:SonarTask",
    "ungm": "replay.tasks.ungm:UNGMTask",
    "gps-odom": "replay.tasks.gps_odom:GpsOdomTask",
    "depth": "replay.tasks.depth:DepthTask",
    "dead-reckoning": "replay.tasks.dead_reckoning:DeadReckoningTask",
    "formation": "replay.tasks.formation:FormationTask",
}


@dataclass
class Problem:
    """Everything a run needs. Filters get ``model, z, x0, P0``; the scorer gets the rest."""

    model: object
    z: np.ndarray  # (n, nz), NaN = missing
    x0: np.ndarray
    P0: np.ndarray
    t: np.ndarray
    truth_position: np.ndarray  # (n, d) reference position, for scoring only
    truth_valid: np.ndarray  # (n,) False where the reference is masked
    position_index: tuple[int, ...]  # state components holding the position
    axis_names: tuple[str, ...]
    truth_angles: dict = field(default_factory=dict)  # name -> (n,) reference angle
    angle_index: dict = field(default_factory=dict)  # name -> state component
    params: dict = field(default_factory=dict)
    truth_extra: dict = field(default_factory=dict)  # name -> ((n,) truth, NaN = not scored; state index)
    lost_threshold: float | None = None  # m: the task's rule for a lost track (None: not judged)
    lost_steps: int = 10


class Task(Declared):
    """A task: keyword-only parameters declared in ``PARAMS``; :meth:`build` makes the problem.

    Every task also declares how a lost track is judged (:mod:`replay.metrics`): a run is
    *lost* when its position error exceeds ``lost_threshold`` metres for ``lost_steps``
    consecutive scored samples. Each task sets its default ``LOST_M`` from the scale of its
    problem; both are parameters (``--task-param lost_threshold=...``), recorded in the manifest.
    """

    KIND = "task"
    name = "task"
    LOST_M: float = 10.0

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "lost_threshold" not in {p.name for p in cls.PARAMS}:
            cls.PARAMS = tuple(cls.PARAMS) + (
                Param("lost_threshold", float, float(cls.LOST_M), "a run whose position error stays above "
                      "this for lost_steps consecutive scored samples is counted lost", unit="m",
                      low=0.0, low_open=True),
                Param("lost_steps", int, 10, "consecutive scored samples above lost_threshold that make a "
                      "run lost", low=1),
            )

    def judge(self, problem: Problem) -> Problem:
        """``problem`` with this task's lost-track rule attached (the scorer applies it)."""
        problem.lost_threshold, problem.lost_steps = self.lost_threshold, self.lost_steps
        return problem

    def build(self, frame, rng: np.random.Generator) -> Problem:
        raise NotImplementedError


def task_class(name: str) -> type[Task]:
    """The class registered as ``name``; an unknown name -> one-line ReplayError listing the known."""
    from replay.util.lookup import resolve

    return resolve(TASKS, name, "task")


def make_task(name: str, **params) -> Task:
    """The task registered as ``name`` with ``params`` (checked against its declarations)."""
    return task_class(name)(**params)


def reference_position_3d(frame, z0: float | None = None):
    """(n, 3) reference position and its validity from the frame's ``position`` reference.

    A 2-D reference (east, north) gets a constant third component ``z0`` (the
    vertical is not observed, as in the Bohai files, whose ``depth`` is zero).
    """
    from replay.util.errors import ReplayError

    ref = frame.reference.get("position")
    if ref is None:
        raise ReplayError(f"{frame.meta.get('dataset') or frame.meta.get('source')}: "
                          "no reference position channel to score against")
    p = ref.values
    if p.shape[1] == 2:
        p = np.column_stack([p, np.full(len(p), 0.0 if z0 is None else z0)])
    return p, ref.valid.copy()
