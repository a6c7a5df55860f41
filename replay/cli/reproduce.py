"""``replay rerun MANIFEST`` (repeat a recorded evaluation and check every recorded result) and
``replay reproduce PAPER`` (a paper's experiments into docs/reproduction/); registered by
:mod:`replay.cli.main`."""

from __future__ import annotations

from pathlib import Path

import click

from replay.cli.run_options import ALLOW_MODULE, DATA_DIR, Existing, quiet_notes, run_option
from replay.util.errors import ReplayError


@click.command("rerun")
@click.argument("manifest_file", type=Existing(dir_okay=False))
@DATA_DIR
@click.option(
    "--out",
    "-o",
    default=None,
    type=click.Path(),
    help="Also write the rerun's leaderboard, manifest and estimates to this directory.",
)
@ALLOW_MODULE
@click.option("--quiet", "-q", is_flag=True, help="No progress display and no notes (errors still print).")
def rerun_cmd(manifest_file, data_dir, out, allow_modules=(), quiet=False):
    """Repeat the run recorded in a manifest.json and check that every recorded result is reproduced exactly."""
    from replay.data.registry import check_data_dir
    from replay.outputs.files import check_output, format_table, write_all
    from replay.run import rerun
    from replay.util.progress import Progress

    check_data_dir(data_dir, "--data-dir")
    man = rerun.load(manifest_file, allow_modules)  # checked before any computation or import
    if out:
        check_output(Path(out), [manifest_file], "--out")
    quiet_notes(quiet)
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


@click.command("reproduce")
@click.argument("paper")
@run_option("runs", "-n", default=None, extra=" Default: the paper's.")
@run_option("seed", "-s")
@DATA_DIR
@click.option(
    "--doc",
    default=None,
    type=click.Path(dir_okay=False),
    help="Markdown report to write (default: docs/reproduction/<paper>.md).",
)
@click.option("--quick", is_flag=True, help="A short version (few runs) for a smoke check.")
@click.option(
    "--part",
    default=None,
    help="Only this part of a reproduction that is split into parts; the document keeps the other parts' sections.",
)
@click.option("--quiet", "-q", is_flag=True, help="No progress lines.")
def reproduce_cmd(paper, runs, seed, data_dir, doc, quick, part, quiet=False):
    """Reproduce a paper's published numbers (PAPER: 000, 001, 002, 003) and print ours beside them."""
    import inspect
    from importlib import import_module

    from replay.data.registry import check_data_dir
    from replay.reproduce import REPRODUCTIONS, run_reproduction

    check_data_dir(data_dir, "--data-dir")  # a mistyped one would silently leave out 002's Bohai rows
    extra = {}
    module, func = REPRODUCTIONS.get(paper.zfill(3), ":").split(":")
    accepts = inspect.signature(getattr(import_module(module), func)).parameters if module else {}
    if part:
        if "part" not in accepts:
            raise ReplayError(f"--part: the reproduction of paper {paper} is not split into parts")
        extra["part"] = part
    if quiet:
        quiet_notes(True)
        if "quiet" in accepts:
            extra["quiet"] = True
    run_reproduction(paper, runs=runs, seed=seed, data_dir=data_dir, doc=doc, quick=quick, **extra)
