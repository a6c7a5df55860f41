"""Per-filter noise settings of a campaign's jobs checked against their task's model, before any unit.

A filter's ``Q``, ``R`` or ``P0`` (:mod:`replay.filters.noise_params`) has the size of the
model the task builds, known only once it is built: run 0's problem of each dataset x task
with such settings is built once here, so that a wrong size (or a model that cannot take
them) stops the campaign in one line instead of failing its units.
"""

from __future__ import annotations

import json

from replay.filters import make_filter
from replay.filters.noise_params import NAMES, check
from replay.run.pipeline import build_problem
from replay.trajectory.recorded import is_recorded
from replay.util.errors import ReplayError

PROBLEM_KEYS = ("dataset", "dataset_params", "first", "task", "task_params", "seed", "adapter")


def check_noise(jobs, where) -> None:
    """Refuse (one line naming ``where``, the dataset, task and filter) a job's noise settings that
    its task's model cannot take; a problem that cannot be built is left to the units to record."""
    models, done = {}, set()
    for job in jobs:
        c = job.config
        if is_recorded(c["filter"]) or not set(c["filter_params"]) & set(NAMES):
            continue
        key = json.dumps([c.get(k) for k in PROBLEM_KEYS], sort_keys=True, default=str)
        if (key, c["filter"], json.dumps(c["filter_params"], sort_keys=True)) in done:
            continue
        done.add((key, c["filter"], json.dumps(c["filter_params"], sort_keys=True)))
        if key not in models:
            try:
                models[key] = build_problem(c, 0, job.data_dir).model
            except Exception:  # noqa: BLE001 — the units record it, as without settings
                models[key] = None
        if models[key] is not None:
            try:
                check(make_filter(c["filter"], **c["filter_params"]), models[key])
            except ReplayError as err:
                raise ReplayError(f"{where}: {c['dataset']}, task {c['task']}: {err}") from None
