"""Tasks: what is measured over a frame, by which model.

A task turns a :class:`replay.frame.Frame` into a :class:`Problem`: the model,
the measurement array the filters see, the prior, and — kept for the scorer
only — the truth. ``TASKS`` maps task names to "module:Class" (a
:class:`replay.util.plugins.Registry`: the built-in tasks, the ``replay.tasks``
entry points of installed distributions, and ``"module:Class"`` names; a plugin task
is a subclass of :class:`Task` defining ``build``, ``docs/plugins.md``). Every task
declares its parameters (``PARAMS``, :mod:`replay.util.params`): they are
checked strictly when the task is made, before any data is read.

**Inputs.** A task finds optional sensor inputs by *role* (:func:`role_input`:
the adapter's ``Frame.roles``, :class:`replay.roles.SensorInput` records declared in a bag
mapping or detected from the message type), never by a channel's name, and records in ``Problem.inputs``
which channels it used (the pipeline puts them in the manifest, beside the
frame's metadata, as ``task_inputs``). A task that finds none of an optional
input says so in ``Problem.notes`` (``task_notes`` in the manifest). A task
that lacks a required channel refuses in one line naming the adapter's report
line that removed it (:func:`missing`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from replay.roles import SensorInput, of_role
from replay.util.errors import ReplayError
from replay.util.params import Declared, Param
from replay.util.plugins import Registry, class_problem
from replay.util.lookup import resolve


def _check(obj):
    """What keeps ``obj`` from being a task, or None."""
    return class_problem(obj, Task, "replay.tasks.Task", (("build",),))


TASKS = Registry(
    "task",
    {
        "position": "replay.tasks.position:PositionTask",
        "sonar": "replay.tasks.sonar:SonarTask",
        "ungm": "replay.tasks.ungm:UNGMTask",
        "linear": "replay.tasks.linear:LinearTask",
        "gps-odom": "replay.tasks.gps_odom:GpsOdomTask",
        "depth": "replay.tasks.depth:DepthTask",
        "dead-reckoning": "replay.tasks.dead_reckoning:DeadReckoningTask",
        "formation": "replay.tasks.formation:FormationTask",
        "fusion": "replay.tasks.fusion:FusionTask",
    },
    check=_check,
)


# the default divergence threshold of every task, times its lost threshold (replay.scoring.metrics): an
# error that large is no lost track but a filter gone numerically wrong with a finite covariance
DIVERGE_FACTOR = 100.0


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
    divergence_threshold: float | None = None  # m: an error beyond it at any scored sample is a divergence
    inputs: dict = field(default_factory=dict)  # what the task used: input -> "channel (source)"
    notes: list = field(default_factory=list)  # one-line notices (e.g. an optional input not found)
    noise: dict = field(default_factory=dict)  # input -> where its measurement noise came from (fusion)
    position_unit: str = "m"  # unit of the position axes ("1": dimensionless, e.g. UNGM)
    extra_units: dict = field(default_factory=dict)  # truth_extra name -> unit (e.g. speed: m/s)


class Task(Declared):
    """A task: keyword-only parameters declared in ``PARAMS``; :meth:`build` makes the problem.

    Every task also declares how a lost track is judged (:mod:`replay.scoring.metrics`): a run is
    *lost* when its position error exceeds ``lost_threshold`` metres for ``lost_steps``
    consecutive scored samples. Each task sets its default ``LOST_M`` from the scale of its
    problem; both are parameters (``--task-param lost_threshold=...``), recorded in the manifest.
    """

    KIND = "task"
    name = "task"
    LOST_M: float = 10.0
    # True when the task draws its measurements from the reference (plus its own noise) instead of
    # reading the recording's sensors: never a recording's default, its rows marked "synthetic"
    SYNTHETIC: bool = False

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "lost_threshold" not in {p.name for p in cls.PARAMS}:
            cls.PARAMS = tuple(cls.PARAMS) + (
                Param(
                    "lost_threshold",
                    float,
                    float(cls.LOST_M),
                    "a run whose position error stays above "
                    "this for lost_steps consecutive scored samples is counted lost",
                    unit="m",
                    low=0.0,
                    low_open=True,
                ),
                Param(
                    "lost_steps", int, 10, "consecutive scored samples above lost_threshold that make a run lost", low=1
                ),
            )

    def judge(self, problem: Problem) -> Problem:
        """``problem`` with this task's lost-track rule attached (the scorer applies it)."""
        problem.lost_threshold, problem.lost_steps = self.lost_threshold, self.lost_steps
        problem.divergence_threshold = DIVERGE_FACTOR * self.lost_threshold
        return problem

    def build(self, frame, rng: np.random.Generator) -> Problem:
        raise NotImplementedError


def task_class(name: str) -> type[Task]:
    """The class registered as ``name``; an unknown name -> one-line ReplayError listing the known."""
    return resolve(TASKS, name, "task")


def make_task(name: str, **params) -> Task:
    """The task registered as ``name`` with ``params`` (checked against its declarations)."""
    return task_class(name)(**params)


def source_of(frame) -> str:
    """The file or dataset a frame came from, for messages."""
    return str(frame.meta.get("source") or frame.meta.get("path") or frame.meta.get("dataset") or "frame")


def simulated(frame, name: str, task: str, hint: str = ""):
    """The simulator's parameter ``name`` that made ``frame`` (``frame.simulation.params``); a frame
    without one (a recording, another simulator) is refused in one line, ``hint`` saying what to do."""
    params = getattr(frame.simulation, "params", None)
    if params is None or not hasattr(params, name):
        made = getattr(frame.simulation, "generator", "") or source_of(frame)
        raise ReplayError(
            f"task {task}: needs the simulator's {name}, which {made} does not declare" + (f"; {hint}" if hint else "")
        )
    return getattr(params, name)


def simulated_start(frame, state: tuple[str, ...], task: str) -> np.ndarray:
    """The simulated initial state of ``frame`` (``frame.simulation``), its components ``state``; else one line."""
    if frame.simulation is None:
        raise ReplayError(
            f"task {task}: needs a simulated initial state ({', '.join(state)}); {source_of(frame)} is not a simulation"
        )
    try:
        return frame.simulation.start(state, f"task {task}")
    except ValueError as e:
        raise ReplayError(str(e)) from None


def describe(frame, name: str, group: str = "channels") -> str:
    """'name (what it holds)' of a channel (or reference channel), for ``Problem.inputs``."""
    ch = getattr(frame, group).get(name)
    if ch is None:
        return name
    return f"{name} ({ch.description})" if ch.description else name


# frames whose adapter declares no roles (``Frame.roles`` None): a channel named as the role
LEGACY_ROLES = {
    "gps": ("gps", {"position": "gps"}),
    "odometry": ("odom", {"velocity": "odom_velocity", "rate": "odom_rate"}),
    "imu": ("imu", {"gyro": "imu"}),
}


def role_input(frame, role: str, task: str) -> SensorInput | None:
    """The frame's input of ``role`` (a :class:`replay.roles.SensorInput`: ``entry``, ``source``,
    ``channels`` = {field: channel name}) or None.

    Adapters that know what their channels are (bags: from the mapping's ``role`` or the
    message type; bohai-csv) list them in ``Frame.roles``; the lookup is by role only,
    whatever the channels are called. Two inputs of one role are refused (one line: keep
    one, e.g. ``role = "none"`` on the others in the mapping). A frame whose ``roles`` is None
    (simulated frames) falls back to a channel named after the role.
    """
    if frame.roles is None:
        if role not in LEGACY_ROLES or LEGACY_ROLES[role][0] not in frame.channels:
            return None
        entry, chans = LEGACY_ROLES[role]
        chans = {k: v for k, v in chans.items() if v in frame.channels}
        return SensorInput(role, entry, frame.channels[entry].description, chans)
    found = [r for r in of_role(frame.roles, role) if any(c in frame.channels for c in r.channels.values())]
    if len(found) > 1:
        raise ReplayError(
            f"{source_of(frame)}: task {task}: {len(found)} inputs have role {role} ("
            + ", ".join(f"{r.entry} = {r.source}" for r in found)
            + "): keep one (role = \"none\" on the others in the mapping)"
        )
    return found[0] if found else None


def why_missing(frame, names) -> str:
    """What the adapter's report says about channels or columns ``names`` (dropped, masked), or ''.

    ``frame.columns`` maps a channel to the columns it is made of (the report names columns).
    """
    wanted = []
    for n in names:
        wanted += [n, *frame.columns.get(n, ())]
    for action in ("dropped", "masked", "flagged"):
        for e in frame.report.entries:
            if e.action == action and e.what in wanted:
                return f"the adapter {action} {e.what} ({e.count} samples: {e.reason})"
    return ""


def missing(frame, task: str, need: str, names=(), hint: str = "") -> ReplayError:
    """The one-line refusal of a task that lacks ``need``: names the report line that removed it."""
    why = why_missing(frame, names or (need,))
    text = f"{source_of(frame)}: task {task} needs {need}"
    if why:
        text += f": {why}"
    elif hint:
        text += f" ({hint})"
    return ReplayError(text)


def reference_position_3d(frame, z0: float | None = None, task: str = "this"):
    """(n, 3) reference position and its validity from the frame's ``position`` reference.

    A 2-D reference (east, north) gets a constant third component ``z0`` (the
    vertical is not observed, as in the Bohai files, whose ``depth`` is zero).
    """
    ref = frame.reference.get("position")
    if ref is None:
        raise missing(frame, task, "a reference position channel to score against", ("position",))
    if not ref.valid.any():
        raise missing(frame, task, "a valid reference position (every sample is masked)", ("position",))
    p = ref.values
    if p.shape[1] == 2:
        p = np.column_stack([p, np.full(len(p), 0.0 if z0 is None else z0)])
    return p, ref.valid.copy()


def reference_present(frame, n: int):
    """(n,) where the reference has a sample at all (a message of its topic, masked or not), or None
    (every sample): on a recording's union time axis the reference is absent at the other topics'
    stamps, which are not *masked* reference samples (the ``masked`` column counts only those)."""
    t = frame.reference.get("position_log_time")
    if t is None or len(t.valid) != n:
        return None
    return np.asarray(t.valid, bool)


def reference_coverage(t, present) -> tuple[int, str | None]:
    """(missing, note) of a reference present only at some steps of the time axis ``t``
    (:func:`reference_present`) that starts after the run or ends before it: the samples its own
    rate (its median step) would have given outside its span count as masked (``missing``), so
    the ``scored`` share says how much of the run was scored; the note says how much of the run's
    time span the reference covers. (0, None) when it covers the run."""
    if present is None or present.sum() < 2:
        return 0, None
    t = np.asarray(t, float)
    at = t[present]
    step = float(np.median(np.diff(at)))
    before, after = at[0] - t[0], t[-1] - at[-1]
    missing = int(before // step + after // step) if step > 0 else 0
    if missing <= 0:
        return 0, None
    span, run = at[-1] - at[0], t[-1] - t[0]
    return missing, (
        f"the reference covers {span:.1f} s of the run's {run:.1f} s ({100 * span / run:.0f} %: "
        f"{at[0] - t[0]:.1f} s to {at[-1] - t[0]:.1f} s); the {missing} samples it would have "
        "given outside (at its median step) count as masked: no result there is scored"
    )
