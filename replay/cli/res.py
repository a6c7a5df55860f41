"""``replay res DIR...``: re-tabulate and re-plot saved results (``replay score --save-results``), as evo_res.

Registered in :mod:`replay.cli.main`. The tables are :mod:`replay.trajectory.res`'s, the archive
:mod:`replay.trajectory.archive`'s, the figure :mod:`replay.trajectory.boxplots`'s.
"""

from __future__ import annotations

from pathlib import Path

import click

from replay.util.errors import ReplayError


@click.command("res")
@click.argument("dirs", nargs=-1, required=True)
@click.option(
    "--table",
    "table",
    type=click.Choice(["stats", "trials"]),
    default="stats",
    show_default=True,
    help="stats: every estimate's APE/RPE (and per-length) statistics; trials: each trial set's "
    "aggregation (mean, median, 95 % t-interval, lost).",
)
@click.option(
    "--format",
    "fmt",
    metavar="csv|md|latex",
    default=None,
    help="Table format (default: from the -o extension .csv/.md/.tex, else md).",
)
@click.option(
    "--digits",
    type=click.IntRange(1, 17),
    default=6,
    show_default=True,
    help="Significant digits of Markdown and LaTeX tables (CSV: every digit).",
)
@click.option(
    "-o",
    "--out",
    "out",
    type=click.Path(dir_okay=False),
    default=None,
    help="Write the table to this file instead of printing it.",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Write the APE over time and boxplots per estimate (png, pdf, svg, eps).",
)
def res_cmd(dirs, table, fmt, digits, out, plot_path):
    """Tables (CSV, Markdown, LaTeX) and plots of results saved by replay score --save-results DIR.

    Given replay eval or campaign outputs, --table trials aggregates their recorded estimates (recorded:NAME
    rows) across the recordings, one trial per directory.
    """
    from replay.trajectory import archive, boxplots, res
    from replay.util import outfile
    from replay.util.files import refuse_overlap

    if fmt is not None and fmt not in res.FORMATS:
        raise ReplayError(f"--format {fmt!r}: expected one of {', '.join(res.FORMATS)}")
    if fmt is None:
        suffix = Path(out).suffix.lower() if out else ""
        if out and suffix not in res.SUFFIXES:
            raise ReplayError(f"-o {out}: give --format csv|md|latex (the extension {suffix or 'none'} does not say)")
        fmt = res.SUFFIXES.get(suffix, "md")
    for path, what, suffixes in ((out, "-o", None), (plot_path, "--plot", boxplots.FORMATS)):
        if path:
            refuse_overlap(path, dirs, what)
            outfile.check(path, what, suffixes)
    archives, boards = [], []
    for d in dirs:
        if not (Path(d) / archive.META).exists() and _is_output(Path(d)):
            from replay.campaign import board

            boards.append((d, board.read_dir(d)))
        else:
            archives.append(archive.load(d))
    if plot_path and boards:
        raise ReplayError(
            f"--plot: {boards[0][0]} is a replay eval or campaign output; --plot draws results archives "
            "(replay report draws eval and campaign outputs)"
        )
    text = res.render(res.rows(archives, table, boards), fmt, digits)
    if out:
        outfile.write(out, "-o", lambda tmp: Path(tmp).write_text(text))
        click.echo(f"table: {out}")
    else:
        click.echo(text, nl=False)
    if plot_path:
        boxplots.write_res(plot_path, archives)
        click.echo(f"plot: {plot_path}")


def _is_output(d: Path) -> bool:
    """A ``replay eval`` output or a campaign directory (its leaderboard is read by ``replay leaderboard``)."""
    from replay.util.staging import read_marker

    mark = read_marker(d) if d.is_dir() else None
    return (mark is not None and mark.get("kind") == "replay eval") or (d / "units").is_dir()
