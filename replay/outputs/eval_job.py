"""``replay eval`` as one library call: :func:`run_eval` checks the whole configuration before any
data is read, claims the output set, evaluates, publishes it and writes the exports.

The command line (:mod:`replay.cli.evaluate`) only parses its options into an
:class:`replay.run.eval_options.EvalOptions` and an :class:`OutputRequest`, calls :func:`run_eval`
and prints (through an :class:`EvalReport`); the Python API (``replay.evaluate(..., out=...)``)
calls the same function.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace

from replay.data import dataset_ref
from replay.outputs.eval_output import EvalOutput
from replay.run.checks import check_config, check_recorded
from replay.run.eval_options import EvalOptions
from replay.run.evaluation import Evaluation, evaluate
from replay.run.pipeline import default_task
from replay.util.errors import ReplayError


@dataclass(frozen=True)
class OutputRequest:
    """Where an evaluation is written: ``out`` (``--out``; None: a new numbered directory
    ``runs/<dataset>/<task>/NNN``, ``latest`` pointing to it), ``force`` (replace an earlier eval
    output at ``out``), ``wait`` (for another writer of ``out`` instead of refusing), and the
    exports of its run 0: ``mcap`` (a Foxglove MCAP file), ``ros2_bag`` (a ROS 2 bag directory)."""

    out: os.PathLike | str | None = None
    force: bool = False
    wait: bool = False
    mcap: os.PathLike | str | None = None
    ros2_bag: os.PathLike | str | None = None


@dataclass(frozen=True)
class EvalRun:
    """What :func:`run_eval` did: the ``evaluation``, the ``paths`` of the output set
    (``leaderboard``, ``manifest``, ``estimates``, ...; ``out``: its directory) and the ``exports``
    written (``{"target", "kind", "messages", "run", "tracks"}`` each)."""

    evaluation: Evaluation
    paths: dict
    exports: list = field(default_factory=list)


class EvalReport:
    """What :func:`run_eval` tells as it goes (the CLI prints it; every method does nothing here but
    :meth:`progress`, which gives ``progress``, a display for the runs, if one is given)."""

    def __init__(self, progress=None):
        self._progress = progress

    def evaluated(self, ev: Evaluation) -> None:
        """The evaluation is computed; the output set is not written yet."""

    def published(self, paths: dict) -> None:
        """The output set is written (``paths``: as :attr:`EvalRun.paths`)."""

    def exported(self, done: dict) -> None:
        """One export is written (as each of :attr:`EvalRun.exports`)."""

    def progress(self, kind: str):
        """A progress display (a :class:`replay.util.progress.Progress`) for the runs of the evaluation
        (``kind`` "eval") or the messages of an export ("mcap", "ros2"), or None; closed when that work
        is done."""
        return self._progress if kind == "eval" else None


def run_eval(dataset, options: EvalOptions, output: OutputRequest, report: EvalReport | None = None) -> EvalRun:
    """Evaluate ``dataset`` under ``options`` and write it as the output set ``output`` (module docstring).
    Everything that can be refused is refused before any data is read (:func:`check_eval`) and before
    anything is computed (the output set and the exports, :class:`EvalOutput`); ``report`` is told
    of each step and gives the progress displays."""
    report = report or EvalReport()
    ref, options = check_eval(dataset, options)
    mapping = (options.dataset_params or {}).get("mapping")
    target = EvalOutput(
        ref,
        dataset,
        options.task,
        output.out,
        force=output.force,
        mapping=mapping,
        exports=(output.mcap, output.ros2_bag),
        data_dir=options.data_dir,
    )
    with target.claimed(output.wait):  # a claimed numbered directory, or --out's lock, until published
        progress = report.progress("eval")
        try:
            ev = evaluate(ref, options, progress=progress)
        finally:
            if progress is not None:
                progress.close()
        report.evaluated(ev)
        paths = dict(target.publish(ev), out=target.out)
        report.published(paths)
        exports = []
        if output.mcap or output.ros2_bag:
            # lazy: the MCAP and ROS 2 writers and their schemas, ~0.25 s of import (-X importtime), for exports only
            from replay.outputs.exports import export_run  # noqa: PLC0415

            for done in export_run(
                target.out, output.mcap, output.ros2_bag, data_dir=options.data_dir, progress=report.progress
            ):
                exports.append(done)
                report.exported(done)
    return EvalRun(ev, paths, exports)


def check_eval(dataset, options: EvalOptions) -> tuple[dataset_ref.DatasetRef, EvalOptions]:
    """The whole configuration checked before any data is read (the baseline among the rows, the
    dataset and its parameters, the task and its parameters, every filter made, the recorded
    estimates the mapping declares): (the dataset resolved, the options with their task named:
    the dataset's default task, which may read a plain file's header)."""
    o = options
    rows = list(o.filters) + list(o.recorded or [])
    if (
        o.baseline is not None
        and o.baseline not in rows
        and not (o.recorded is None and o.baseline.startswith("recorded:"))
    ):
        raise ReplayError(f"--baseline {o.baseline!r}: not among --filters ({', '.join(rows)})")
    ref = dataset_ref.resolve(dataset, o.adapter)  # the id parsed once, handed down
    dparams = o.dataset_params or {}
    check_config(ref, o.task, list(o.filters), o.filter_params, o.task_params, dparams, adapter=o.adapter)
    check_recorded(ref.id, o.recorded or [], dparams)  # before any recording is read
    task = o.task or default_task(
        ref, first=o.first, data_dir=o.data_dir, adapter=o.adapter, dataset_params=dparams, seed=o.seed
    )
    return ref, replace(o, task=task)
