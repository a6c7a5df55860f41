"""``replay campaign run``, ``replay leaderboard``, ``replay report``."""

from __future__ import annotations

import os
from pathlib import Path

import click

from replay.cli.run_options import ALLOW_MODULE, DATA_DIR, Existing
from replay.util.errors import ReplayError
from replay.util.files import check_writable, refuse_overlap


@click.group("campaign")
def campaign():
    """Evaluation campaigns: datasets x tasks x filters x parameters x runs, resumable."""


NAME_MAX = 255  # bytes of one file name (Linux, macOS, Windows file systems)


def check_names(out, what: str) -> None:
    """Refuse a path with a name longer than file systems allow, before any work."""
    for part in Path(out).parts:
        if len(os.fsencode(part)) > NAME_MAX:
            shown = str(out) if len(str(out)) <= 80 else str(out)[:60] + "..."
            raise ReplayError(
                f"{what} {shown}: a name in it is {len(os.fsencode(part))} bytes long (file systems allow {NAME_MAX})"
            )


@campaign.command("run")
@click.argument("file", type=click.Path(dir_okay=False))
@click.option(
    "--out",
    "-o",
    default=None,
    type=click.Path(file_okay=False),
    help="Result directory (default: runs/campaign-<name>).",
)
@click.option(
    "--workers",
    "-w",
    default=None,
    type=click.IntRange(1),
    help="Local worker processes (default: all cores; 1 = in this process).",
)
@click.option("--scheduler", default=None, help="Dask scheduler address, e.g. tcp://host:8786.")
@click.option("--dask-local", default=None, type=click.IntRange(1), help="Start a Dask LocalCluster of N workers.")
@DATA_DIR
@click.option("--retry-failed", is_flag=True, help="Compute failed units again.")
@ALLOW_MODULE
@click.option("--quiet", "-q", is_flag=True, help="No progress output.")
@click.option(
    "--wait",
    is_flag=True,
    help="If another campaign process is writing to the result directory, wait for it instead of refusing.",
)
def run_cmd(file, out, workers, scheduler, dask_local, data_dir, retry_failed, quiet, wait, allow_modules=()):
    """Run the units of campaign FILE not yet stored in the result directory."""
    from replay.campaign import board, execute, lock, spec

    if sum(x is not None for x in (workers, scheduler, dask_local)) > 1:
        raise ReplayError("give at most one of --workers, --scheduler, --dask-local")
    c = spec.load(file, allow_modules)  # a module:Class name refused before anything is imported
    from replay.tune import campaign as tune_campaign

    tunes = tune_campaign.plan(c, data_dir)  # a [tune] table: checked before any unit too
    out = Path(out) if out else Path("runs") / f"campaign-{c.name}"
    check_names(out, "--out")
    # never onto or inside the data; absent, empty or a campaign's own directory: replay eval's rule
    lock.output_set(out, [c.data_dir, data_dir]).check()
    counts = execute.run(
        c,
        out,
        execute.RunOptions(
            workers=workers,
            scheduler=scheduler,
            dask_local=dask_local,
            quiet=quiet,
            retry_failed=retry_failed,
            data_dir=data_dir,
            wait=wait,
        ),
    )
    for key, what in (
        ("rewritten", "rewrote {n} damaged configuration file{s}"),
        ("missing", "recomputed {n} missing configuration{s}"),
        ("damaged", "recomputed {n} damaged unit{s}"),
    ):
        found = counts[key]
        if found:
            more = f"; and {len(found) - 5} more" if len(found) > 5 else ""
            click.echo(what.format(n=len(found), s="s" * (len(found) != 1)) + ": " + "; ".join(found[:5]) + more)
    if not quiet:
        click.echo(board.format_rows(counts["rows"]))
    if counts["units"] == 0:
        click.echo(f"nothing to do: all {counts['stored_before']} units already stored in {out}")
    else:
        click.echo(
            f"{counts['done']} units computed, {counts['failed']} failed ({counts['backend']}); "
            f"wrote {out / 'leaderboard.csv'}, {out / 'paired.csv'}"
        )
    for name, t in tunes:  # replay tune at scale: every tune's units in one store, OUT/tune
        from replay.tune import run as tune_run
        from replay.tune.write import board_notes, format_board

        res = tune_run.tune(
            t,
            out / "tune" / name,
            store_dir=out / "tune",
            workers=workers,
            scheduler=scheduler,
            dask_local=dask_local,
            quiet=quiet,
            wait=wait,
        )
        click.echo(f"tune {name} ({t.split.tuned_on} -> {t.split.tested_on}; {t.trials} trials per filter):")
        click.echo(format_board(res["rows"]))
        for line in board_notes(res["rows"], res.get("failed")):
            click.echo(line)
        click.echo("wrote " + ", ".join(str(p) for p in res["paths"].values()))


@click.command("leaderboard")
@click.argument("dirs", nargs=-1, required=True, type=Existing())
@click.option("--sort", default=None, help="Sort by this column (ascending), e.g. pos_rmse, ate.")
@click.option("--out", "-o", default=None, type=click.Path(dir_okay=False), help="Write the merged CSV here.")
def leaderboard(dirs, sort, out):
    """Merge the leaderboards of result directories (campaigns or `replay eval` outputs)."""
    from replay.campaign import board

    if out:
        check_names(out, "--out")
        refuse_overlap(out, dirs, "--out")
        check_writable(out, "--out")
    rows = board.merge(dirs, sort)
    click.echo(board.format_rows(rows))
    if out:
        board._write(rows, Path(out), board.merged_columns(rows))
        click.echo(f"wrote {out}")


@click.command("report")
@click.argument("dir", type=Existing(file_okay=False))
@click.option(
    "--out",
    "-o",
    default=None,
    type=click.Path(file_okay=False),
    help="Where to write the PNGs and report.html (default: DIR/report).",
)
def report(dir, out):
    """Summary, leaderboards and figures (trajectories, error bands, metrics, NEES/NIS) in one HTML page."""
    from replay.outputs.report import make_report
    from replay.tune import report as tune_report

    if out:
        check_names(out, "--out")
    if tune_report.is_tune_dir(Path(dir)):  # replay tune: history, importances, train-versus-test gap
        make_report = tune_report.make_report
    path = make_report(Path(dir), Path(out) if out else None)
    click.echo(f"wrote {path}")


COMMANDS = (campaign, leaderboard, report)
