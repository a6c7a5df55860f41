"""The options of ``replay tune`` (and of a campaign file's ``[tune]`` table, ``replay eval --tune``), declared
once (:data:`TUNE_OPTIONS`: those of an evaluation reused from :mod:`replay.run.eval_options`, the tune's own
here) and their record, :class:`TuneOptions`: built once at the edge and passed whole to
:func:`replay.tune.check.prepare`. Its fields are the declarations (checked at import) plus the filters and
the search space's entries (checked by ``prepare``); each declared value is checked when the record is made."""

from __future__ import annotations

import os
from dataclasses import dataclass, replace

from replay.run.eval_options import BY_NAME as EVAL
from replay.util.errors import ReplayError
from replay.util.params import Param, check_fields, declared_fields

TUNE_OPTIONS = (
    replace(EVAL["runs"], default=20, doc="Monte Carlo runs per configuration"),  # replay tune's -n default
    EVAL["seed"],
    EVAL["first"],
    EVAL["alignment"],
    Param("dataset", os.PathLike, None, "the dataset tuned on and tested on (or --train and --test)", optional=True),
    EVAL["task"],
    EVAL["task_params"],
    EVAL["dataset_params"],
    Param("view", dict, None, "dataset view: {rate, window}, as replay eval's", optional=True),
    EVAL["data_dir"],
    Param("trials", int, 50, "trials per filter (the same for each)", low=1),
    Param("objective", str, "mean_rmse", "mean_rmse, median_rmse, lost, nll, anees, or weighted:NAME=W,NAME=W"),
    Param("train_segment", str, None, "train on this first fraction of the dataset's duration", optional=True),
    Param("train", str, None, "training dataset ids, comma-separated (with test)", optional=True),
    Param("test", str, None, "test dataset ids, comma-separated (with train)", optional=True),
    Param("split", str, None, "'seeds': simulated data, train on seed, test on seed + 1", optional=True),
    Param("allow_overlap", bool, False, "allow training and test data to overlap (flagged on every row)"),
    replace(EVAL["batch"], default=None, optional=True, doc="runs computed at once (null: the campaign default)"),
)


@dataclass(frozen=True)
class TuneOptions:
    """What ``replay tune`` is asked: the declared options (:data:`TUNE_OPTIONS`), the ``filters`` tuned
    (names) and the search space's ``entries`` (:func:`replay.tune.space.entries_from_cli` and ``_from_file``)."""

    filters: tuple | list
    entries: list
    runs: int = 20
    seed: int = EVAL["seed"].default
    first: int | None = EVAL["first"].default
    alignment: str = EVAL["alignment"].default
    dataset: os.PathLike | str | None = None
    task: str | None = None
    task_params: dict | None = None
    dataset_params: dict | None = None
    view: dict | None = None
    data_dir: os.PathLike | str | None = None
    trials: int = 50
    objective: str = "mean_rmse"
    train_segment: str | None = None
    train: str | None = None
    test: str | None = None
    split: str | None = None
    allow_overlap: bool = False
    batch: int | None = None

    def __post_init__(self):
        t = self.trials
        if not isinstance(t, int) or isinstance(t, bool) or t < 1:
            raise ReplayError(f"--trials {t}: at least 1 trial per filter")
        check_fields(self, TUNE_OPTIONS)


declared_fields(TuneOptions, TUNE_OPTIONS)
