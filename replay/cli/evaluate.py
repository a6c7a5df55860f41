"""``replay eval DATASET``: filters over a dataset, scored, written as one output set (and exported);
registered by :mod:`replay.cli.main`."""

from __future__ import annotations

import sys

import click

from replay.cli.eval_tune import data_options, tune_options
from replay.cli.run_options import ALLOW_MODULE, DATA_DIR, MAPPING, Existing, quiet_notes, run_option
from replay.cli.view_options import view_options


@click.command("eval")
@click.argument("dataset")
@click.option("--task", "-t", default=None, help="Task (default: the dataset's default task).")
@click.option(
    "--filters",
    "-f",
    default="ekf,ukf,ckf,pf",
    show_default=True,
    help="Comma-separated filter names; 'none' for no filter. Recorded estimates of the mapping's "
    "[estimates] are scored beside them as rows recorded:<name> (all by default; name some "
    "as recorded:<name>, or recorded:none for none).",
)
@run_option("runs", "-n")
@run_option("seed", "-s")
@run_option("first")
@click.option(
    "--out",
    "-o",
    default=None,
    type=click.Path(),
    help="Output directory (default: a new numbered one, runs/<dataset>/<task>/NNN, "
    "with runs/<dataset>/<task>/latest pointing to it).",
)
@click.option(
    "--force", is_flag=True, help="Replace --out if it holds an earlier replay eval output (never anything else)."
)
@click.option(
    "--wait",
    is_flag=True,
    help="If another replay eval is writing to --out, wait for it to finish instead of refusing.",
)
@click.option("--quiet", "-q", is_flag=True, help="No progress display and no notes (errors still print).")
@DATA_DIR
@click.option("--adapter", default=None, help="Adapter for a plain file (default: chosen from the file).")
@click.option(
    "--param",
    "-p",
    "params",
    multiple=True,
    help="Filter parameter FILTER.NAME=VALUE, e.g. pf.n_particles=500 (repeatable; "
    "VALUE is JSON; `replay list filters` shows every filter's parameters).",
)
@click.option(
    "--task-param", "task_params", multiple=True, help="Task parameter NAME=VALUE (repeatable; `replay list tasks`)."
)
@click.option(
    "--dataset-param",
    "dataset_params",
    multiple=True,
    help="Dataset parameter NAME=VALUE, e.g. q=10 for sim/ungm (repeatable; `replay list datasets`).",
)
@click.option(
    "--baseline", default=None, help="Filter the leaderboard's paired columns compare with (default: the first listed)."
)
@MAPPING
@click.option(
    "--mcap", "mcap_out", default=None, type=click.Path(), help="Also export the run as a Foxglove MCAP file."
)
@click.option(
    "--ros2-bag",
    "ros2_out",
    default=None,
    type=click.Path(),
    help="Also export the run as a ROS 2 bag (MCAP storage) directory.",
)
@run_option("alignment")
@run_option("divergence_threshold")
@click.option(
    "--min-scored-share",
    default=None,
    type=float,
    help="Flag rows scored on a smaller share of the reference samples (default: 0.5; the rest is masked).",
)
@click.option(
    "--tuned",
    default=None,
    type=Existing(dir_okay=False),
    help="A tuned.toml of replay tune: its filters (unless --filters), filter and task parameters; on the "
    "dataset it was tested on, also its test data (views, --first, dataset parameters; a differing one is "
    "refused) and its --runs, --seed, --alignment unless given, so that it gives the tune's held-out rows.",
)
@ALLOW_MODULE
@view_options
@tune_options
def eval_cmd(
    dataset,
    task,
    filters,
    runs,
    seed,
    first,
    out,
    data_dir,
    adapter,
    params,
    task_params,
    dataset_params,
    baseline,
    mapping,
    mcap_out,
    ros2_out,
    alignment,
    divergence_threshold,
    force,
    quiet,
    wait,
    min_scored_share,
    rate,
    window,
    segment,
    fault,
    tuned,
    tune_trials=None,
    tune_repeats=None,
    train_segment=None,
    tune_space=None,
    tune_grid=None,
    tune_objective=None,
    allow_modules=(),
):
    """Run filters on DATASET (an id such as bohai/20220822_0_6, or a file), print and write the leaderboard."""
    quiet_notes(quiet)  # before default_task, which may load the file (its progress is a note)
    if any(v is not None for v in (tune_trials, tune_repeats, train_segment, tune_space, tune_grid, tune_objective)):
        from replay.cli import eval_tune

        return eval_tune.from_cli(dataset, locals())  # --tune N: replay.tune.repeat
    from replay.outputs.eval_job import OutputRequest, run_eval

    options = eval_options(dataset, locals())
    done = run_eval(dataset, options, OutputRequest(out, force, wait, mcap_out, ros2_out), Printed(quiet))
    _failed_filters(done.evaluation)


def eval_options(dataset, o: dict):
    """``replay eval``'s options (``o``: its arguments) as one :class:`replay.run.eval_options.EvalOptions`
    (with ``--tuned``: :func:`replay.tune.tuned.with_tuned`, told which options the command line gave)."""
    from replay.cli import params as cli_params
    from replay.run.eval_options import EvalOptions
    from replay.scoring.summary import MIN_SCORED_SHARE

    tparams, dparams = data_options(o)
    share = o["min_scored_share"]
    share = MIN_SCORED_SHARE.check(MIN_SCORED_SHARE.default if share is None else share, "--min-scored-share")
    names, recorded = cli_params.split_filters(f.strip() for f in o["filters"].split(",") if f.strip())
    options = EvalOptions(
        task=o["task"],
        filters=names,
        recorded=recorded,
        filter_params=cli_params.filter_params(o["params"], names + (recorded or [])),
        task_params=tparams,
        dataset_params=dparams or None,
        **{k: o[k] for k in ("runs", "seed", "first", "data_dir", "adapter", "alignment", "baseline")},
        divergence_threshold=o["divergence_threshold"],
        min_scored_share=share,
    )
    if not o["tuned"]:
        return options
    from replay.tune.tuned import RUN_OPTIONS, with_tuned

    ctx = click.get_current_context()
    given = {k for k in ("filters", *RUN_OPTIONS) if ctx.get_parameter_source(k) != click.core.ParameterSource.DEFAULT}
    options, note = with_tuned(o["tuned"], dataset, options, given, o["allow_modules"])
    if note and not o["quiet"]:
        click.echo(f"replay: note: {note}", err=True)
    return options


class Printed:
    """``replay eval``'s display (the methods of :class:`replay.outputs.eval_job.EvalReport`): the progress
    on stderr (none when ``quiet``), the leaderboard, its notes and the paths written on stdout."""

    def __init__(self, quiet: bool):
        self.quiet = quiet

    def progress(self, kind: str):
        from replay.cli.bags import export_progress
        from replay.util.progress import Progress

        return (
            Progress(0, self.quiet, label="eval", unit="run") if kind == "eval" else export_progress(kind, self.quiet)
        )

    def evaluated(self, ev) -> None:
        from replay.outputs.files import format_table
        from replay.scoring import outages

        for note in [] if self.quiet else ev.frame_meta.get("task_notes", []):
            click.echo(f"replay: note: {note}", err=True)
        click.echo(format_table(ev))
        if outages.is_outages(ev):  # fusion score=outages: the end-of-outage errors, the headline
            click.echo(outages.format_headline(outages.tables(ev)[1]))
        for note in ev.notes:
            click.echo(note)

    def published(self, paths: dict) -> None:
        click.echo(f"wrote {paths['leaderboard']}, {paths['manifest']}, {paths['estimates']}/")

    def exported(self, done: dict) -> None:
        from replay.cli.bags import echo_export

        echo_export(done)


def _failed_filters(ev) -> None:
    """A filter that failed (a plugin's bug, sys.exit, memory, a broken protocol): one warning line
    each, after the other filters' results are written, and exit status 1."""
    from replay.run.manifest import failures

    bad = failures(ev)
    for name, f in bad.items():
        click.echo(
            f"replay: warning: filter {name!r}: {len(f['runs'])} of {ev.config['runs']} runs failed "
            f"({f['error']}); recorded in the leaderboard's failed column and the manifest",
            err=True,
        )
    if bad:
        sys.exit(1)
