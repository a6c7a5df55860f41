"""replay: replay real navigation logs through state-estimation filters and score them.

The Python API (``docs/python.md``), imported on first use::

    import replay
    frame = replay.load_frame("bohai/20220822_0_6", data_dir="../shared/datasets/bohai")
    ev = replay.evaluate("sim/auv-sonar", filters=["ekf", "ukf"], runs=20)
    ev.leaderboard()            # a pandas DataFrame: the values of leaderboard.csv

Every name of :data:`__all__` is a function of :mod:`replay.api`, imported on first use.
``replay.evaluate`` and ``replay.score`` are those functions; the modules behind them are
:mod:`replay.run.evaluation`, :mod:`replay.scoring.scorer` and :mod:`replay.trajectory.score_api`
(no submodule shares an API name).
"""

import importlib as _importlib

from replay.util.version import __version__  # noqa: F401  (a leaf: importlib.metadata)

__all__ = [
    "campaign_results",
    "evaluate",
    "export_mcap",
    "frame_table",
    "list_plugins",
    "load_frame",
    "load_trajectory",
    "make_filter",
    "make_task",
    "plot_errors",
    "plot_paired",
    "plot_rmse",
    "plot_track",
    "refresh_plugins",
    "register_filter",
    "register_task",
    "report_table",
    "run_campaign",
    "score",
]


def __getattr__(name):
    if name in __all__:
        return getattr(_importlib.import_module(f"{__name__}.api"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
