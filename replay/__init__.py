"""replay: replay real navigation logs through state-estimation filters and score them.

The Python API (``docs/python.md``), imported on first use::

    import replay
    frame = replay.load_frame("bohai/20220822_0_6", data_dir="../shared/datasets/bohai")
    ev = replay.evaluate("sim/auv-sonar", filters=["ekf", "ukf"], runs=20)
    ev.leaderboard()            # a pandas DataFrame: the values of leaderboard.csv

Every name of :data:`__all__` comes from :mod:`replay.api`. ``replay.evaluate`` and
``replay.score`` are also the modules of those names (``replay.evaluate.Evaluation``,
``from replay import score``): the modules are callable, and calling one calls the API
function of its name (:func:`replay.api.evaluate`, :func:`replay.api.score`).
"""
import importlib as _importlib
import sys as _sys
import types as _types

from replay.util.version import __version__  # noqa: E402,F401  (a leaf: importlib.metadata)

__all__ = ["campaign_results", "evaluate", "export_mcap", "frame_table", "list_plugins", "load_frame",
           "load_trajectory", "make_filter", "make_task", "plot_errors", "plot_paired", "plot_rmse",
           "plot_track", "refresh_plugins", "register_filter", "register_task", "report_table", "run_campaign",
           "score"]
CALLABLE_MODULES = ("evaluate", "score")  # submodules that are also API functions


class _CallableModule(_types.ModuleType):
    """``replay.evaluate`` / ``replay.score``: the module, and called, the API function of its name."""

    def __call__(self, *args, **kwargs):
        return getattr(_importlib.import_module("replay.api"), self.__name__.rpartition(".")[2])(*args, **kwargs)

    @property
    def __signature__(self):
        import inspect

        return inspect.signature(getattr(_importlib.import_module("replay.api"), self.__name__.rpartition(".")[2]))


class _Package(_types.ModuleType):
    def __setattr__(self, name, value):
        # the import system sets each submodule as an attribute of its package once loaded
        if (name in CALLABLE_MODULES and type(value) is _types.ModuleType
                and getattr(value, "__name__", "") == f"{__name__}.{name}"):
            value.__class__ = _CallableModule
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package


def __getattr__(name):
    if name in CALLABLE_MODULES:
        return _importlib.import_module(f"{__name__}.{name}")
    if name in __all__:
        return getattr(_importlib.import_module(f"{__name__}.api"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
