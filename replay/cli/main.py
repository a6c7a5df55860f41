"""The ``replay`` command line.

Bad input raises :class:`replay.util.errors.ReplayError`; :class:`Main` turns it into
one line on stderr and exit status 2 (no traceback).
"""
from __future__ import annotations

import sys
from pathlib import Path

import click

from replay.cli.examples import add_examples
from replay.cli.view_options import view_options, with_views
from replay.util.errors import ReplayError
from replay.util.version import __version__


class Main(click.Group):
    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except ReplayError as err:
            click.echo(f"replay: error: {err}", err=True)
            ctx.exit(2)
        except MemoryError as err:  # not predicted (replay.resources): said as such, never "diverged"
            click.echo(f"replay: error: out of memory{f' ({err})' if str(err) else ''}", err=True)
            ctx.exit(2)
        finally:
            import gc

            gc.freeze()  # the exit's last collection skips what the command built (~0.2 s after a campaign)


@click.group(cls=Main)
@click.version_option(__version__, prog_name="replay")
def main():
    """Replay navigation logs through state-estimation filters and score them."""
    _notes_to_stderr()


def _quiet(quiet: bool) -> None:
    """``-q``: the library's notes (logger ``replay``) down to warnings."""
    if quiet:
        import logging

        logging.getLogger("replay").setLevel(logging.WARNING)


def _notes_to_stderr() -> None:
    """One-line notices of the library (logger ``replay``: e.g. a one-time kernel compilation) on
    stderr, as ``replay: note: ...``; ``-q`` of a command raises the level to warnings."""
    import logging

    log = logging.getLogger("replay")
    if not any(getattr(h, "_replay_cli", False) for h in log.handlers):
        from replay.util.progress import NoteHandler  # a live progress bar is erased first

        h = NoteHandler(sys.stderr)
        h.setFormatter(logging.Formatter("replay: note: %(message)s"))
        h._replay_cli = True
        log.addHandler(h)
        log.propagate = False
    log.setLevel(logging.INFO)


@main.command("eval")
@click.argument("dataset")
@click.option("--task", "-t", default=None, help="Task (default: the dataset's default task).")
@click.option("--filters", "-f", default="ekf,ukf,ckf,pf", show_default=True,
              help="Comma-separated filter names; 'none' for no filter. Recorded estimates of the mapping's "
                   "[estimates] are scored beside them as rows recorded:<name> (all by default; name some "
                   "as recorded:<name>, or recorded:none for none).")
@click.option("--runs", "-n", default=1, show_default=True, type=int, help="Monte Carlo runs (1 to 1000000).")
@click.option("--seed", "-s", default=0, show_default=True, type=int, help="Master seed (an integer >= 0).")
@click.option("--first", default=None, type=int, help="Use only the first N samples.")
@click.option("--out", "-o", default=None, type=click.Path(),
              help="Output directory (default: a new numbered one, runs/<dataset>/<task>/NNN, "
                   "with runs/<dataset>/<task>/latest pointing to it).")
@click.option("--force", is_flag=True, help="Replace --out if it holds an earlier replay eval output "
              "(never anything else).")
@click.option("--wait", is_flag=True, help="If another replay eval is writing to --out, wait for it to "
              "finish instead of refusing.")
@click.option("--quiet", "-q", is_flag=True, help="No progress display and no notes (errors still print).")
@click.option("--data-dir", default=None, type=click.Path(), help="Where to look for dataset files first.")
@click.option("--adapter", default=None, help="Adapter for a plain file (default: chosen from the file).")
@click.option("--param", "-p", "params", multiple=True,
              help="Filter parameter FILTER.NAME=VALUE, e.g. pf.n_particles=500 (repeatable; "
                   "VALUE is JSON; `replay list filters` shows every filter's parameters).")
@click.option("--task-param", "task_params", multiple=True,
              help="Task parameter NAME=VALUE (repeatable; `replay list tasks`).")
@click.option("--dataset-param", "dataset_params", multiple=True,
              help="Dataset parameter NAME=VALUE, e.g. q=10 for sim/ungm (repeatable; `replay list datasets`).")
@click.option("--baseline", default=None,
              help="Filter the leaderboard's paired columns compare with (default: the first listed).")
@click.option("--mapping", default=None, type=click.Path(exists=True, dir_okay=False),
              help="Topic mapping (TOML) for a bag or MCAP file (docs/bags.md).")
@click.option("--mcap", "mcap_out", default=None, type=click.Path(),
              help="Also export the run as a Foxglove MCAP file.")
@click.option("--ros2-bag", "ros2_out", default=None, type=click.Path(),
              help="Also export the run as a ROS 2 bag (MCAP storage) directory.")
@click.option("--alignment", default="se3", show_default=True,
              help="Alignment of the estimate onto the reference for the ATE column: none, yaw, se3, sim3.")
@click.option("--divergence-threshold", default=None, type=float,
              help="Position error (m) beyond which a run counts as diverged (default: none).")
@click.option("--min-scored-share", default=None, type=float,
              help="Flag rows scored on a smaller share of the reference samples (default: 0.5; "
                   "the rest is masked).")
@click.option("--tuned", default=None, type=click.Path(exists=True, dir_okay=False),
              help="A tuned.toml of replay tune: its filters (unless --filters), filter and task parameters.")
@view_options
def eval_cmd(dataset, task, filters, runs, seed, first, out, data_dir, adapter, params, task_params,
             dataset_params=(), baseline=None, mapping=None, mcap_out=None, ros2_out=None, alignment="se3",
             divergence_threshold=None, force=False, quiet=False, wait=False, min_scored_share=None,
             rate=None, window=None, segment=None, tuned=None):
    """Run filters on DATASET (an id such as bohai/20220822_0_6, or a file), print and write the leaderboard."""
    _quiet(quiet)  # before default_task, which may load the file (its progress is a note)
    from replay.cli import params as cli_params
    from replay.eval_options import validate_eval_options
    from replay.evaluation import check_recorded, evaluate
    from replay.outputs.files import check_location, check_output, eval_inputs, format_table, write_all
    from replay.outputs.rundirs import claimed_run_dir, mark_latest, new_run_dir, out_locked
    from replay.pipeline import default_task
    from replay.registry import check_data_dir
    from replay.summary import MIN_SCORED_SHARE

    check_data_dir(data_dir, "--data-dir")
    min_scored_share = MIN_SCORED_SHARE.check(MIN_SCORED_SHARE.default if min_scored_share is None
                                              else min_scored_share, "--min-scored-share")
    validate_eval_options({"runs": runs, "seed": seed, "first": first, "alignment": alignment,
                           "divergence_threshold": divergence_threshold})  # the API's declarations and messages
    names, recorded = cli_params.split_filters(f.strip() for f in filters.split(",") if f.strip())
    if baseline is not None and baseline not in names + (recorded or []) and not (
            recorded is None and baseline.startswith("recorded:")):
        raise ReplayError(f"--baseline {baseline!r}: not among --filters ({', '.join(names + (recorded or []))})")
    fparams = cli_params.filter_params(params, names + (recorded or []))
    tparams = cli_params.task_params(task_params, task)
    if tuned:  # replay tune's tuned.toml: its filters and their parameters (-p and --task-param win)
        from replay.tune.tuned import tuned_params

        given = click.get_current_context().get_parameter_source("filters") != click.core.ParameterSource.DEFAULT
        t_names, t_fparams, t_tparams, task = tuned_params(tuned, task)
        names = names if given else t_names
        fparams = {n: {**t_fparams.get(n, {}), **fparams.get(n, {})} for n in names if n in t_fparams or n in fparams}
        tparams = {**t_tparams, **tparams}
    dparams = with_views(cli_params.dataset_inputs(dataset_params, mapping), rate, window, segment)
    cli_params.check_config(dataset, task, names, fparams, tparams, dparams, adapter=adapter)
    check_recorded(dataset, recorded or [], dparams)  # before any recording is read
    # the output set is checked before the computation (inputs, writable, space, ownership)
    task = task or default_task(dataset, first=first, data_dir=data_dir, adapter=adapter,
                                dataset_params=dparams, seed=seed)
    numbered = out is None
    inputs = eval_inputs(dataset, data_dir, mapping)
    if numbered:  # the location, before claiming a number in it
        check_location(new_run_dir(dataset, task), inputs, "--out")
    else:
        check_output(Path(out), inputs, "--out")
        _fresh(Path(out), force)
    _check_exports(new_run_dir(dataset, task) if numbered else Path(out), mcap_out, ros2_out, dataset, mapping,
                   data_dir)
    from contextlib import ExitStack

    with ExitStack() as held:  # a claimed numbered directory, or --out's lock, until published
        out = held.enter_context(claimed_run_dir(dataset, task)) if numbered else Path(out)
        if not numbered:
            held.enter_context(out_locked(out, wait))
        check_output(out, inputs, "--out")  # again, now that no other replay eval writes there
        _fresh(out, numbered or force)
        _check_exports(out, mcap_out, ros2_out, dataset, mapping, data_dir)
        from replay.util.progress import Progress

        _quiet(quiet)
        progress = Progress(0, quiet, label="eval", unit="run")
        try:
            ev = evaluate(dataset, task=task, filters=names, runs=runs, seed=seed, first=first,
                          data_dir=data_dir, filter_params=fparams,
                          task_params=tparams, adapter=adapter,
                          dataset_params=dparams or None, alignment=alignment,
                          divergence_threshold=divergence_threshold, baseline=baseline, recorded=recorded,
                          progress=progress, min_scored_share=min_scored_share)
        finally:
            progress.close()
        for note in ([] if quiet else ev.frame_meta.get("task_notes", [])):
            click.echo(f"replay: note: {note}", err=True)
        click.echo(format_table(ev))
        for note in ev.notes:
            click.echo(note)
        _fresh(out, numbered or force)  # again at publication
        paths = write_all(ev, out, what="--out")
        if numbered:
            mark_latest(out)
        click.echo(f"wrote {paths['leaderboard']}, {paths['manifest']}, {paths['estimates']}/")
        if mcap_out or ros2_out:
            from replay.cli.bags import export_outputs

            export_outputs(out, mcap_out, ros2_out, data_dir=data_dir, quiet=quiet)
    _failed_filters(ev)


def _check_exports(out: Path, mcap_out, ros2_out, dataset, mapping, data_dir) -> None:
    """--mcap and --ros2-bag: not inside or around the output directory, writable (before computing)."""
    for opt, path in (("--mcap", mcap_out), ("--ros2-bag", ros2_out)):
        if path and (Path(path).resolve().is_relative_to(out.resolve())
                     or out.resolve().is_relative_to(Path(path).resolve())):
            raise ReplayError(f"{opt} {path}: overlaps the output directory {out}, which is replaced as a whole")
    if mcap_out or ros2_out:
        from replay.cli.bags import check_eval_exports

        check_eval_exports(out, mcap_out, ros2_out, dataset, mapping, data_dir)


def _fresh(out: Path, replace: bool) -> None:
    """Without --force, refuse an --out that holds an output (checked at the start and again
    before publication, under --out's lock)."""
    if not replace and out.is_dir() and any(out.iterdir()):
        raise ReplayError(f"--out {out}: holds an earlier replay eval output; pass --force to replace it, "
                          "or leave out --out for a new numbered directory")


def _failed_filters(ev) -> None:
    """A filter that failed (a plugin's bug, sys.exit, memory, a broken protocol): one warning line
    each, after the other filters' results are written, and exit status 1."""
    from replay.evaluation import failures

    bad = failures(ev)
    for name, f in bad.items():
        click.echo(f"replay: warning: filter {name!r}: {len(f['runs'])} of {ev.config['runs']} runs failed "
                   f"({f['error']}); recorded in the leaderboard's failed column and the manifest", err=True)
    if bad:
        sys.exit(1)


@main.command("rerun")
@click.argument("manifest_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--data-dir", default=None, type=click.Path(), help="Where to look for dataset files first.")
@click.option("--out", "-o", default=None, type=click.Path(),
              help="Also write the rerun's leaderboard, manifest and estimates to this directory.")
@click.option("--allow-module", "allow_modules", multiple=True, metavar="MODULE",
              help="Let the manifest name a filter, task or adapter as 'MODULE:Class' (importing MODULE runs its "
                   "code); without it only built-in and installed (entry-point) ones are loaded. Repeatable.")
@click.option("--quiet", "-q", is_flag=True, help="No progress display and no notes (errors still print).")
def rerun_cmd(manifest_file, data_dir, out, allow_modules=(), quiet=False):
    """Repeat the run recorded in a manifest.json and check that every recorded result is reproduced exactly."""
    from replay import rerun
    from replay.outputs.files import check_output, format_table, write_all
    from replay.util.progress import Progress

    from replay.registry import check_data_dir

    check_data_dir(data_dir, "--data-dir")
    man = rerun.load(manifest_file, allow_modules)  # checked before any computation or import
    if out:
        check_output(Path(out), [manifest_file], "--out")
    _quiet(quiet)
    progress = Progress(0, quiet, label="rerun", unit="run")
    try:
        ev = rerun.repeat(man, data_dir, progress=progress)
    finally:
        progress.close()
    click.echo(format_table(ev))
    if out:
        write_all(ev, Path(out))
    rerun.verify(man, ev, manifest_file)
    click.echo("reproduced: every recorded result equals the rerun's (timing and versions not compared)")


@main.command("reproduce")
@click.argument("paper")
@click.option("--runs", "-n", default=None, type=click.IntRange(1), help="Monte Carlo runs (default: the paper's).")
@click.option("--seed", "-s", default=0, show_default=True, type=int)
@click.option("--data-dir", default=None, type=click.Path())
@click.option("--doc", default=None, type=click.Path(dir_okay=False),
              help="Markdown report to write (default: docs/reproduction/<paper>.md).")
@click.option("--quick", is_flag=True, help="A short version (few runs) for a smoke check.")
@click.option("--part", default=None, help="Only this part of a reproduction split into parts "
              "(002: tables, ablations, bohai, all); the document keeps the other parts' sections.")
@click.option("--quiet", "-q", is_flag=True, help="No progress lines.")
def reproduce_cmd(paper, runs, seed, data_dir, doc, quick, part, quiet=False):
    """Reproduce a paper's published numbers (PAPER: 000, 001, 002, 003) and print ours beside them."""
    import inspect

    from replay.reproduce import REPRODUCTIONS, run_reproduction

    from importlib import import_module

    extra = {}
    module, func = REPRODUCTIONS.get(paper.zfill(3), ":").split(":")
    accepts = inspect.signature(getattr(import_module(module), func)).parameters if module else {}
    if part:
        if "part" not in accepts:
            raise ReplayError(f"--part: the reproduction of paper {paper} is not split into parts")
        extra["part"] = part
    if quiet:
        _quiet(True)
        if "quiet" in accepts:
            extra["quiet"] = True
    run_reproduction(paper, runs=runs, seed=seed, data_dir=data_dir, doc=doc, quick=quick, **extra)


def _register_optional():
    from replay.cli.datasets import datasets
    from replay.cli.listing import list_cmd

    main.add_command(datasets)
    main.add_command(list_cmd)
    from replay.cli.bags import export_cmd, inspect_cmd

    main.add_command(inspect_cmd)
    main.add_command(export_cmd)
    from replay.cli.score import score_cmd

    main.add_command(score_cmd)
    from replay.cli.tune import tune_cmd

    main.add_command(tune_cmd)
    from replay.cli.campaign import COMMANDS as campaign_commands

    for cmd in campaign_commands:
        main.add_command(cmd)


_register_optional()
add_examples(main)

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
