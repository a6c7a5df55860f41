"""What the exports read from a `replay eval` output directory, and how they place it in space.

:func:`load_run` reads ``manifest.json`` and run 0 of ``estimates/<filter>.csv.gz``,
reloads the dataset named in the manifest (same adapter, mapping, ``first`` and, for
a simulator, the run-0 seed) and rebuilds the task problem for the reference. No
filter is run again.

East-north-up: exported poses are in the local ENU frame (frame id ``enu``). A task
names its position axes; :func:`enu_axes` maps ``x``/``east``, ``y``/``north``,
``z``/``up`` to themselves and ``depth``/``down`` to minus up, so that a
north-east-down task (dead reckoning: ``north, east, depth``) is not exported with
north as east. Its heading (clockwise from north) becomes the ENU yaw
(anticlockwise from east): ``yaw = pi/2 - heading`` (:func:`enu_yaw`). Axis names
outside that list are taken in order as x, y, z.
"""
from __future__ import annotations

import gzip
import json
import warnings
import zlib
from pathlib import Path

import numpy as np

from replay.util.errors import DataError, ReplayError


def load_run(run_dir, data_dir=None) -> dict:
    """The manifest's config, run-0 estimates per filter, the frame and the rebuilt problem."""
    from replay import registry
    from replay.tasks import make_task
    from replay.util.seeds import rng_for

    run_dir = Path(run_dir)
    path = run_dir / "manifest.json"
    try:
        cfg = json.loads(path.read_text())["config"]
        dataset, seed, names = cfg["dataset"], cfg["seed"], list(cfg["filters"])
        dparams, tparams = dict(cfg.get("dataset_params") or {}), dict(cfg.get("task_params") or {})
    except FileNotFoundError:
        raise DataError(path, "no such file: not a `replay eval` output directory") from None
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise DataError(path, f"not a replay manifest ({e})") from None
    for name in names:
        if not isinstance(name, str) or not name or Path(name).name != name or name.startswith("."):
            raise DataError(path, f"filter name {name!r} is not a plain name")
    # the simulator's generator is seeded as in run 0
    frame = registry.load_frame(dataset, data_dir=data_dir, rng=rng_for(seed, 0, 0), first=cfg.get("first"),
                                adapter=cfg.get("adapter"), **dparams)
    problem = make_task(cfg["task"], **tparams).build(frame, rng_for(seed, 0, 1))
    estimates = {name: read_estimates(run_dir / "estimates" / f"{name}.csv.gz") for name in names}
    return {"config": cfg, "frame": frame, "problem": problem, "estimates": estimates}


def _run_rows(fh, run: int):
    """The lines of one run: the writer puts each run's rows together, runs in order."""
    seen = False
    for line in fh:
        try:
            this = float(line.split(",", 1)[0])
        except ValueError:
            this = None  # let the parser name the bad row
        if this == run or (this is None and seen):
            seen = True
            yield line
        elif seen:
            return


def read_estimates(path, run: int = 0) -> dict:
    """``{t, x, P, err}`` of one run from an ``estimates/<filter>.csv.gz`` file.

    Only that run's rows are read (they are together in the file; the reading stops at
    the next run), so the memory does not grow with the number of runs.
    """
    try:
        with gzip.open(path, "rt") as fh:
            head = fh.readline().strip().split(",")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "input contained no data": refused below
                data = np.loadtxt(_run_rows(fh, run), delimiter=",", ndmin=2)
    except FileNotFoundError:
        raise DataError(path, "no such estimates file") from None
    except (OSError, ValueError, EOFError, zlib.error) as e:
        raise DataError(path, f"cannot read estimates ({e})") from None
    nx = sum(1 for h in head if h.startswith("x") and h[1:].isdigit())
    if not len(data) or data.shape[1] != len(head):
        raise DataError(path, f"no rows of run {run}" if not len(data) else
                        f"{data.shape[1]} columns for the {len(head)} of the header")
    if not np.array_equal(data[:, 1], np.arange(len(data))):
        raise DataError(path, f"the rows of run {run} are not its steps 0, 1, 2, ... in order")
    n_err = data.shape[1] - 3 - 2 * nx
    return {"t": data[:, 2], "x": data[:, 3:3 + nx], "P": data[:, 3 + nx:3 + 2 * nx],
            "err": data[:, 3 + 2 * nx:3 + 2 * nx + n_err]}


def time_ns(frame, t) -> np.ndarray:
    """Absolute nanoseconds of frame times ``t``: meta t0_ns, else epoch, else 0, plus t."""
    t0 = frame.meta.get("t0_ns")
    if t0 is None:
        t0 = int(round(frame.epoch * 1e9)) if frame.epoch is not None else 0
    return int(t0) + np.round(np.asarray(t, float) * 1e9).astype(np.int64)


def heading_index(problem):
    """The state component holding the heading (or yaw), or None."""
    for name in ("heading", "yaw", "psi"):
        if name in problem.angle_index:
            return problem.angle_index[name]
    angles = getattr(problem.model, "x_angles", ())
    return angles[0] if len(angles) == 1 else None


_SLOT = {"x": (0, 1), "east": (0, 1), "y": (1, 1), "north": (1, 1), "z": (2, 1), "up": (2, 1),
         "depth": (2, -1), "down": (2, -1)}


def enu_axes(problem) -> list[tuple[int, int]]:
    """(ENU slot, sign) of each position component of the task (see the module docstring)."""
    names = [str(a).lower() for a in problem.axis_names]
    if len(names) != len(problem.position_index) or not 1 <= len(names) <= 3:
        raise ReplayError(f"export: task with position axes {tuple(problem.axis_names)}: "
                          "cannot place them in east-north-up (1 to 3 axes)")
    slots = [_SLOT.get(n) for n in names]
    if None in slots or len({s for s, _ in slots}) < len(slots):
        return [(i, 1) for i in range(len(names))]
    return slots


def to_enu(p, axes) -> np.ndarray:
    """(n, 3) east-north-up positions from the task's position components ``p`` (n, d)."""
    p = np.asarray(p, float)
    out = np.zeros((len(p), 3))
    for i, (slot, sign) in enumerate(axes):
        out[:, slot] = p[:, i] if sign > 0 else -p[:, i]
    return out


def ned(problem) -> bool:
    """Whether the task's frame is north-east-down (its heading clockwise from north)."""
    return [str(a).lower() for a in problem.axis_names[:2]] == ["north", "east"]


def enu_yaw(heading, is_ned: bool):
    """ENU yaw (anticlockwise from east) of the task's heading."""
    return np.pi / 2 - heading if is_ned else heading
