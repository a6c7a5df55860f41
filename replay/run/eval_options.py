"""The options of an evaluation, declared once: ``replay eval``, :func:`replay.evaluate` and
campaign files validate them with :func:`validate_eval_options` (same one-line messages).

:class:`EvalOptions` is their record: built once at the edge (the CLI, :func:`replay.evaluate`, a
manifest's rerun) and passed whole to :func:`replay.run.evaluation.evaluate`; its fields are the
declarations (checked at import), each value checked by its declaration when the record is made.

Each is a :class:`replay.util.params.Param` (type, default, bounds, unit, doc); the API's
argument declarations (:mod:`replay.api_args`) reuse them, and the hostile API test
generates its bad calls from them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from replay.scoring.align import ALIGNMENTS
from replay.data.registry import FIRST
from replay.util.errors import ReplayError
from replay.scoring.summary import MIN_SCORED_SHARE
from replay.util.params import Param, check_fields, declared_fields

MAX_RUNS = 1_000_000  # beyond, a run count is a typo; what fits in memory is checked too (replay.run.resources)
MAX_SEED = 2**63 - 1  # a TOML / JSON integer

EVAL_OPTIONS = (
    Param("task", str, None, "task (default: the dataset's default task)", optional=True),
    Param("runs", int, 1, "Monte Carlo runs", unit="runs", low=1, high=MAX_RUNS),
    Param("seed", int, 0, "master seed of every run's random streams", low=0, high=MAX_SEED),
    FIRST,  # replay.data.registry.load_frame checks it too
    Param("data_dir", os.PathLike, None, "where to look for dataset files first", optional=True),
    Param("adapter", str, None, "adapter for a plain file (default: chosen from the file)", optional=True),
    Param("task_params", dict, None, "task parameters (replay list tasks)", optional=True),
    Param("dataset_params", dict, None, "dataset parameters (replay list datasets)", optional=True),
    Param(
        "alignment", str, "se3", "alignment of the estimate onto the reference for the ATE column", choices=ALIGNMENTS
    ),
    Param(
        "divergence_threshold",
        float,
        None,
        "position error beyond which a run counts as diverged (null: none)",
        unit="m",
        low=0.0,
        low_open=True,
        optional=True,
    ),
    Param("baseline", str, None, "row the paired columns compare with (default: the first)", optional=True),
    Param("batch", int, 25, "runs computed at once (a block)", unit="runs", low=1, high=MAX_RUNS),
)
BY_NAME = {p.name: p for p in EVAL_OPTIONS}
DEFAULTS = {p.name: p.default for p in EVAL_OPTIONS}  # written once, in the declarations


def validate_eval_options(options: dict, where: str = "") -> dict:
    """``options`` checked against :data:`EVAL_OPTIONS` and normalised (ints of float options as
    floats, numpy integers as ints); only the names given are returned. An unknown name or a
    value outside its declaration raises one line, prefixed by ``where`` (a campaign file) when given."""
    prefix = f"{where}: " if where else ""
    out = {}
    for name, value in options.items():
        if name not in BY_NAME:
            raise ReplayError(f"{prefix}unknown option {name!r} (known: {', '.join(BY_NAME)})")
        out[name] = BY_NAME[name].check(value, where)
    return out


DEFAULT_FILTERS = ("ekf", "ukf", "ckf", "pf")


@dataclass(frozen=True)
class EvalOptions:
    """Everything an evaluation is asked besides its dataset: the declared options (:data:`EVAL_OPTIONS`,
    their defaults), the rows (``filters``: names; ``filter_params``: {filter: {name: value}};
    ``recorded``: recorded estimates added by name, None: every one the frame holds that ``filters``
    does not name) and ``min_scored_share`` (:data:`replay.scoring.summary.MIN_SCORED_SHARE`)."""

    task: str | None = DEFAULTS["task"]
    runs: int = DEFAULTS["runs"]
    seed: int = DEFAULTS["seed"]
    first: int | None = DEFAULTS["first"]
    data_dir: os.PathLike | str | None = DEFAULTS["data_dir"]
    adapter: str | None = DEFAULTS["adapter"]
    task_params: dict | None = DEFAULTS["task_params"]
    dataset_params: dict | None = DEFAULTS["dataset_params"]
    alignment: str = DEFAULTS["alignment"]
    divergence_threshold: float | None = DEFAULTS["divergence_threshold"]
    baseline: str | None = DEFAULTS["baseline"]
    batch: int = DEFAULTS["batch"]
    filters: tuple | list = DEFAULT_FILTERS
    filter_params: dict | None = None
    recorded: tuple | list | None = ()
    min_scored_share: float = MIN_SCORED_SHARE.default

    def __post_init__(self):
        check_fields(self, (MIN_SCORED_SHARE, *EVAL_OPTIONS))  # evaluate's order of old


declared_fields(EvalOptions, (*EVAL_OPTIONS, MIN_SCORED_SHARE))
