"""The arguments of every public API function (``replay.__all__``), declared once, and
:func:`checked`, which validates them before the function runs.

Scalars and paths are :class:`replay.util.params.Param` declarations (the options of an
evaluation are those of :mod:`replay.run.eval_options`, shared with ``replay eval`` and
campaign files); objects (an Evaluation, a Frame, a class) are :class:`Kind`. A bad
argument, a wrong number of arguments or an unknown keyword raises one-line
:class:`~replay.util.errors.ReplayError`, the CLI's message. As a last guard, a TypeError,
ValueError, IndexError, KeyError, AttributeError, OSError or MemoryError ("out of memory")
escaping a public function is raised as a ReplayError naming the function (the original
chained as its cause).
"""

from __future__ import annotations

import functools
import importlib
import inspect
import os
from dataclasses import dataclass, replace

from replay.scoring.align import ALIGNMENTS
from replay.run.eval_options import BY_NAME as EVAL
from replay.run.failures import describe
from replay.scoring.summary import MIN_SCORED_SHARE
from replay.trajectory.files import FORMATS
from replay.trajectory.pose_error import DELTA_UNITS, EVO_NAMES, RELATIONS
from replay.util.errors import ReplayError, shown
from replay.util.params import Param


@dataclass(frozen=True)
class Kind:
    """An argument that must be an instance (or, ``cls=True``, a subclass) of ``of``, given as
    ``"module:Class"`` (imported when checked)."""

    name: str
    of: str
    doc: str
    cls: bool = False
    optional: bool = False

    def check(self, value, owner: str = ""):
        wants = [getattr(importlib.import_module(m), a) for m, _, a in (o.partition(":") for o in self.of.split("|"))]
        ok = (value is None and self.optional) or any(
            inspect.isclass(value) and issubclass(value, w) if self.cls else isinstance(value, w) for w in wants
        )
        if not ok:
            what = " or ".join(
                f"a subclass of {w.__name__}"
                if self.cls
                else f"{'an' if w.__name__[0] in 'AEIOU' else 'a'} {w.__name__}"
                for w in wants
            )
            shown = value.__name__ if inspect.isclass(value) else type(value).__name__
            raise ReplayError(
                f"{owner + ': ' if owner else ''}{self.name} must be {what}"
                f"{' (or None)' if self.optional else ''} (got {shown})"
            )
        return value


@dataclass(frozen=True)
class Either:
    """An argument that one of several declarations accepts (``seed``: an integer or a Generator)."""

    name: str
    options: tuple

    def check(self, value, owner: str = ""):
        for d in self.options:
            try:
                return d.check(value, owner)
            except ReplayError:
                pass
        what = " or ".join(d.accepts() if isinstance(d, Param) else d.doc for d in self.options)
        shown = repr(value) if isinstance(value, (int, float, str, bytes, type(None))) else type(value).__name__
        raise ReplayError(f"{owner + ': ' if owner else ''}{self.name} must be {what} (got {shown:.60})")


@dataclass(frozen=True)
class Several:
    """An argument that is one item or a non-empty list (or tuple) of items, each accepted by
    ``item`` (a declaration of the same name): ``estimates``, ``pose_relation``."""

    name: str
    item: object
    optional: bool = False

    def check(self, value, owner: str = ""):
        if value is None and self.optional:
            return None
        if not isinstance(value, (list, tuple)):
            return self.item.check(value, owner)
        if not value:
            raise ReplayError(
                f"{owner + ': ' if owner else ''}{self.name} must be one item or a non-empty list (got an empty list)"
            )
        return [replace(self.item, name=f"{self.name}[{k}]").check(v, owner) for k, v in enumerate(value)]


def _p(name, type_, doc, **kw):
    return Param(name, type_, kw.pop("default", None), doc, **kw)


PATH = functools.partial(_p, type_=os.PathLike)
DATASET = PATH(name="dataset", doc="a dataset id (replay datasets list) or a file path (a string or a pathlib.Path)")
EVALUATION = Kind("ev", "replay.run.evaluation:Evaluation", "an evaluation (replay.evaluate)")
FRAME = Kind("frame", "replay.frame:Frame", "a frame (replay.load_frame)")


def TRAJECTORY(name):  # noqa: N802 — a declaration
    return Either(
        name,
        (
            PATH(name=name, doc="a trajectory file or BAG:topic"),
            Kind(name, "replay.trajectory.base:Trajectory", "a Trajectory (replay.load_trajectory)"),
            Kind(name, "pandas:DataFrame", "a DataFrame with columns t, x, y, z[, qx, qy, qz, qw]"),
        ),
    )


NAME = _p("name", str, "a registered name", optional=True)

SEED = Either(
    "seed", (EVAL["seed"], Kind("seed", "numpy.random:Generator", "a numpy.random.Generator (or None)", optional=True))
)
SOURCE = Kind("source", "replay.run.evaluation:Evaluation|replay.frame:Frame", "an evaluation or a frame")

ARGS: dict[str, dict] = {
    "evaluate": {
        "dataset": DATASET,
        **{k: v for k, v in EVAL.items() if k != "batch"},
        "batch": EVAL["batch"],
        "filter_params": _p("filter_params", dict, "{filter: {name: value}}", optional=True),
        "min_scored_share": MIN_SCORED_SHARE,
        "out": PATH(name="out", doc="write replay eval's output set into this directory", optional=True),
        "force": _p("force", bool, "replace an earlier replay eval output at out", default=False),
    },
    "load_frame": {
        "dataset": DATASET,
        "data_dir": EVAL["data_dir"],
        "seed": SEED,
        "first": EVAL["first"],
        "adapter": EVAL["adapter"],
    },
    "campaign_results": {
        "out": PATH(name="out", doc="a result directory"),
        "runs": _p("runs", bool, "one row per run", default=False),
    },
    "export_mcap": {
        "evaluation": Kind("evaluation", "replay.run.evaluation:Evaluation", "an evaluation"),
        "path": PATH(name="path", doc="the MCAP file to write"),
        "run": _p("run", int, "the run exported", default=0, low=0),
        "data_dir": EVAL["data_dir"],
    },
    "frame_table": {
        "frame": FRAME,
        "reference": _p("reference", bool, "reference channels", default=False),
        "masks": _p("masks", bool, "mask columns", default=False),
        "time": _p("time", str, "time column", default="relative", choices=("relative", "utc")),
    },
    "report_table": {"frame": FRAME},
    "make_filter": {"name": _p("name", str, "a filter name (replay list filters)")},
    "make_task": {"name": _p("name", str, "a task name (replay list tasks)")},
    "plot_errors": {"ev": EVALUATION},
    "plot_paired": {"ev": EVALUATION, "metric": _p("metric", str, "a leaderboard metric", default="pos_rmse")},
    "plot_rmse": {"ev": EVALUATION, "metric": _p("metric", str, "a leaderboard metric", default="pos_rmse")},
    "plot_track": {
        "source": SOURCE,
        "utm": _p("utm", bool, "UTM axes", default=True),
        "run": _p("run", int, "the run drawn", default=0, low=0),
    },
    "register_filter": {"cls": Kind("cls", "replay.filters.base:Filter", "a Filter subclass", cls=True), "name": NAME},
    "register_task": {"cls": Kind("cls", "replay.tasks:Task", "a Task subclass", cls=True), "name": NAME},
    "run_campaign": {
        "campaign": PATH(name="campaign", doc="a campaign file (TOML)"),
        "out": PATH(name="out", doc="the result directory"),
        "workers": _p("workers", int, "worker processes", low=1, high=4096, optional=True),
        "data_dir": EVAL["data_dir"],
        "quiet": _p("quiet", bool, "no progress", default=True),
        "retry_failed": _p("retry_failed", bool, "compute failed units again", default=False),
    },
    "load_trajectory": {"source": PATH(name="source", doc="a trajectory file or BAG:topic")},
    "score": {
        "reference": TRAJECTORY("reference"),
        "estimates": Several("estimates", TRAJECTORY("estimates"), optional=True),
        "trials": Either(
            "trials",
            (
                _p("trials", str, "[NAME=]GLOB", optional=True),
                Kind("trials", "builtins:list|builtins:tuple", "a list of sources (one set)"),
                Kind("trials", "builtins:dict", "{name: glob or list of sources}"),
            ),
        ),
        "align": _p("align", str, "alignment", default="none", choices=(*ALIGNMENTS, "scale")),
        "n_to_align": _p("n_to_align", int, "poses aligned", low=1, optional=True),
        "align_origin": _p("align_origin", bool, "align the first poses", default=False),
        "t_max_diff": _p("t_max_diff", float, "association tolerance", default=0.01, unit="s", low=0.0),
        "t_offset": _p("t_offset", float, "added to the estimate's stamps", default=0.0, unit="s"),
        "pose_relation": Several(
            "pose_relation",
            _p("pose_relation", str, "pose relation", default="trans", choices=(*RELATIONS, *EVO_NAMES)),
        ),
        "rpe": _p("rpe", bool, "also the RPE", default=False),
        "delta": _p("delta", float, "RPE pose distance", low=0.0, low_open=True, optional=True),
        "delta_unit": _p("delta_unit", str, "unit of delta", default="f", choices=DELTA_UNITS),
        "delta_tol": _p("delta_tol", float, "relative delta tolerance", default=0.1, low=0.0),
        "all_pairs": _p("all_pairs", bool, "every pair at delta", default=False),
        "pairs_from_reference": _p("pairs_from_reference", bool, "pairs from the reference", default=False),
        "fmt": _p("fmt", str, "format of the files", choices=FORMATS, optional=True),
        "kitti_times": PATH(name="kitti_times", doc="stamps of KITTI poses", optional=True),
        "columns": Either(
            "columns",
            (
                _p("columns", str, "columns of a plain CSV", optional=True),
                _p("columns", dict, "columns of a plain CSV"),
            ),
        ),
        "time_unit": _p("time_unit", str, "unit of CSV stamps", choices=("s", "ms", "us", "ns"), optional=True),
        "lost_threshold": _p("lost_threshold", float, "lost above", unit="m", low=0.0, low_open=True, optional=True),
        "lost_steps": _p("lost_steps", int, "consecutive poses", default=10, low=1),
        "names": Several("names", _p("names", str, "names of the estimates"), optional=True),
        "lengths": Either(
            "lengths",
            (_p("lengths", str, "lengths, e.g. 10%,20% or 100,200 (m)", optional=True), _p("lengths", list, "lengths")),
        ),
        "lengths_method": _p("lengths_method", str, "sub-trajectories", default="rpg", choices=("rpg", "kitti")),
        "sync_method": _p("sync_method", str, "association", default="nearest", choices=("nearest", "interpolation")),
        "t_start": _p("t_start", float, "first stamp scored", unit="s", optional=True),
        "t_end": _p("t_end", float, "last stamp scored", unit="s", optional=True),
        "downsample": _p("downsample", int, "poses kept", low=2, optional=True),
        "motion_filter": _p("motion_filter", list, "(metres, degrees)", length=2, optional=True),
        "project_to_plane": _p("project_to_plane", str, "plane", choices=("xy", "xz", "yz"), optional=True),
    },
    "list_plugins": {},
    "refresh_plugins": {},
}
# the functions whose keyword options are all declared: an unknown one is refused with the known ones
CLOSED = {"evaluate": ("recorded", "progress"), "score": ()}


def default(decl):
    """The default of a declaration (a :class:`Param`'s; an optional one's None; a list's, its item's)."""
    if isinstance(decl, Several):
        return None if decl.optional else default(decl.item)
    if isinstance(decl, Either):
        return default(decl.options[0])
    return getattr(decl, "default", None)


def _run_in(source, run, owner):
    """``run`` must be a run of the evaluation (a frame has one)."""
    n = len(source.results[0].records) if hasattr(source, "results") and source.results else 1
    if run >= n:
        raise ReplayError(f"{owner}: run {run}: the evaluation has runs 0..{n - 1}")


def _metric_in(ev, metric, owner):
    known = sorted({k for r in ev.rows for k, v in r.items() if isinstance(v, (int, float))})
    if metric not in known:
        raise ReplayError(
            f"{owner}: metric {shown(metric)} is not a leaderboard column "
            f"(numeric columns: {', '.join(known[:12])}, ...)"
        )


# relations between arguments, checked after each alone: {function: check(arguments, owner)}
RELATIONS = {
    "export_mcap": lambda a, o: _run_in(a["evaluation"], a.get("run", 0), o),
    "plot_track": lambda a, o: _run_in(a["source"], a.get("run", 0), o),
    "plot_rmse": lambda a, o: _metric_in(a["ev"], a.get("metric", "pos_rmse"), o),
}
GUARDED = (TypeError, ValueError, IndexError, KeyError, AttributeError, OSError)


def checked(name: str, fn):
    """``fn`` (the public function ``name``) with its declared arguments (:data:`ARGS`) checked first."""
    sig, decl = inspect.signature(fn), ARGS[name]

    @functools.wraps(fn)
    def call(*args, **kwargs):
        try:
            bound = sig.bind(*args, **kwargs)
        except TypeError as err:
            raise ReplayError(f"replay.{name}: {err}") from None
        for key, value in list(bound.arguments.items()):
            kind = sig.parameters[key].kind
            if kind is inspect.Parameter.VAR_KEYWORD:
                if name in CLOSED and (bad := [k for k in value if k not in decl and k not in CLOSED[name]]):
                    known = [k for k in (*decl, *CLOSED[name]) if k not in sig.parameters or k == key]
                    raise ReplayError(f"replay.{name}: unknown option {shown(bad[0])} (known: {', '.join(known)})")
                bound.arguments[key] = {k: decl[k].check(v) if k in decl else v for k, v in value.items()}
            elif key in decl:
                bound.arguments[key] = decl[key].check(value)
        if name in RELATIONS:
            RELATIONS[name](bound.arguments, f"replay.{name}")
        try:
            return fn(*bound.args, **bound.kwargs)
        except ReplayError:
            raise
        except GUARDED + (MemoryError,) as err:
            raise ReplayError(f"replay.{name}: {describe(err)[:300]}") from err

    return call
