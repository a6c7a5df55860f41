"""``replay eval DATASET``: filters over a dataset, scored, written as one output set (and exported);
registered by :mod:`replay.cli.main`."""

from __future__ import annotations

import sys

import click

from replay.cli.eval_tune import tune_options
from replay.cli.run_options import ALLOW_MODULE, DATA_DIR, MAPPING, quiet_notes, run_option
from replay.cli.view_options import view_options, with_views
from replay.util.errors import ReplayError


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
    type=click.Path(exists=True, dir_okay=False),
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
    from replay.data.registry import check_data_dir
    from replay.outputs.eval_output import EvalOutput
    from replay.scoring.summary import MIN_SCORED_SHARE

    check_data_dir(data_dir, "--data-dir")
    min_scored_share = MIN_SCORED_SHARE.check(
        MIN_SCORED_SHARE.default if min_scored_share is None else min_scored_share, "--min-scored-share"
    )
    run = dict(runs=runs, seed=seed, first=first, alignment=alignment, divergence_threshold=divergence_threshold)
    ref, names, recorded, fparams, tparams, dparams, task = _configuration(
        dataset,
        task,
        filters,
        params,
        task_params,
        dataset_params,
        mapping,
        baseline,
        tuned,
        (rate, window, segment, fault),
        adapter,
        run,
        data_dir,
        quiet,
        allow_modules,
    )
    output = EvalOutput(
        ref, dataset, task, out, force=force, mapping=mapping, exports=(mcap_out, ros2_out), data_dir=data_dir
    )
    with output.claimed(wait):  # a claimed numbered directory, or --out's lock, until published
        ev = _evaluate(
            ref,
            quiet,
            task=task,
            filters=names,
            data_dir=data_dir,
            filter_params=fparams,
            task_params=tparams,
            adapter=adapter,
            dataset_params=dparams or None,
            baseline=baseline,
            recorded=recorded,
            min_scored_share=min_scored_share,
            **run,
        )
        _publish(ev, output, quiet)
    _failed_filters(ev)


def _evaluate(ref, quiet: bool, **options):
    """:func:`replay.run.evaluation.evaluate` with a progress display (none when ``quiet``)."""
    from replay.run.eval_options import EvalOptions
    from replay.run.evaluation import evaluate
    from replay.util.progress import Progress

    quiet_notes(quiet)
    progress = Progress(0, quiet, label="eval", unit="run")
    try:
        return evaluate(ref, EvalOptions(**options), progress=progress)
    finally:
        progress.close()


def _configuration(
    dataset,
    task,
    filters,
    params,
    task_params,
    dataset_params,
    mapping,
    baseline,
    tuned,
    views,
    adapter,
    run,
    data_dir,
    quiet,
    allow_modules=(),
):
    """``replay eval``'s configuration from its options, checked whole before any data is read:
    (the dataset resolved once, filters, recorded estimates, filter, task and dataset parameters, task).
    ``run`` (runs, seed, first, alignment, divergence_threshold) is updated in place from ``--tuned``."""
    from replay.cli import params as cli_params
    from replay.data import dataset_ref
    from replay.run.checks import check_recorded
    from replay.run.pipeline import default_task

    names, recorded = cli_params.split_filters(f.strip() for f in filters.split(",") if f.strip())
    if (
        baseline is not None
        and baseline not in names + (recorded or [])
        and not (recorded is None and baseline.startswith("recorded:"))
    ):
        raise ReplayError(f"--baseline {baseline!r}: not among --filters ({', '.join(names + (recorded or []))})")
    fparams = cli_params.filter_params(params, names + (recorded or []))
    tparams = cli_params.task_params(task_params, task)
    if tuned:  # replay tune's tuned.toml: its filters and their parameters (-p and --task-param win)
        from replay.tune.tuned import tuned_params

        given = click.get_current_context().get_parameter_source("filters") != click.core.ParameterSource.DEFAULT
        t_names, t_fparams, t_tparams, task = tuned_params(tuned, task, allow_modules)
        names = names if given else t_names
        fparams = {n: {**t_fparams.get(n, {}), **fparams.get(n, {})} for n in names if n in t_fparams or n in fparams}
        tparams = {**t_tparams, **tparams}
    dparams = with_views(cli_params.dataset_inputs(dataset_params, mapping), *views)
    ref = dataset_ref.resolve(dataset, adapter)  # the id parsed once, handed down
    if tuned:  # the data the tune tested on: its views, first, runs and seed (issue 40 item 1)
        dparams, run["first"], new, note = _tuned_data(tuned, ref, dparams, run)
        run.update(new)
        if note and not quiet:
            click.echo(f"replay: note: {note}", err=True)
    cli_params.check_config(ref, task, names, fparams, tparams, dparams, adapter=adapter)
    check_recorded(ref.id, recorded or [], dparams)  # before any recording is read
    task = task or default_task(
        ref, first=run["first"], data_dir=data_dir, adapter=adapter, dataset_params=dparams, seed=run["seed"]
    )
    return ref, names, recorded, fparams, tparams, dparams, task


def _tuned_data(tuned, ref, dparams, run):
    """:func:`replay.tune.tuned.tuned_data` with the run options given on the command line."""
    from replay.tune.tuned import RUN_OPTIONS, tuned_data

    ctx = click.get_current_context()
    given = {k for k in RUN_OPTIONS if ctx.get_parameter_source(k) != click.core.ParameterSource.DEFAULT}
    opts = {k: run[k] for k in RUN_OPTIONS}
    return tuned_data(tuned, ref, dparams, run["first"], opts, given)


def _publish(ev, output, quiet: bool) -> None:
    """Print the leaderboard and write the output set (then the exports): ``output.publish``."""
    from replay.outputs.files import format_table

    for note in [] if quiet else ev.frame_meta.get("task_notes", []):
        click.echo(f"replay: note: {note}", err=True)
    click.echo(format_table(ev))
    from replay.scoring import outages

    if outages.is_outages(ev):  # fusion score=outages: the end-of-outage errors, the headline
        click.echo(outages.format_headline(outages.tables(ev)[1]))
    for note in ev.notes:
        click.echo(note)
    paths = output.publish(ev)
    click.echo(f"wrote {paths['leaderboard']}, {paths['manifest']}, {paths['estimates']}/")
    mcap_out, ros2_out = output.exports
    if mcap_out or ros2_out:
        from replay.cli.bags import export_outputs

        export_outputs(output.out, mcap_out, ros2_out, data_dir=output.data_dir, quiet=quiet)


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
