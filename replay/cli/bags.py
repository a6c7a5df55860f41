"""`replay inspect FILE` and `replay export RUN_DIR`: ROS bags / MCAP in and out.

Errors are raised as ReplayError; the top-level `replay` command prints them on
one line and exits with status 2.
"""

from __future__ import annotations

from pathlib import Path

import click

from replay.cli.run_options import DATA_DIR
from replay.util.errors import ReplayError


@click.command("inspect")
@click.argument("path", type=click.Path())
@click.option(
    "--write-mapping",
    default=None,
    type=click.Path(dir_okay=False),
    help="Write the proposed mapping to this TOML file.",
)
def inspect_cmd(path, write_mapping):
    """List the topics of a bag or MCAP (type, count, rate, span) and propose a topic mapping."""
    from replay.adapters.bags import inspect
    from replay.util import outfile
    from replay.util.files import refuse_overlap

    if write_mapping:  # before the bag is read: a writable file, never onto or inside the bag
        outfile.check(write_mapping, "--write-mapping")
        refuse_overlap(write_mapping, [path], "--write-mapping")
    info = inspect(path)
    click.echo(f"{info['path']}  format={info['format']}  messages={info['messages']}  span={info['span_s']:.3f} s")
    if info["truncated"]:
        click.echo(f"TRUNCATED: {info['truncated']} (counts are what could be read)")
    head = ("topic", "type", "count", "rate Hz", "span s", "first stamp s", "mapped")
    rows = [head]
    for r in info["topics"]:
        stamp = f"{r['first_stamp_s']:.3f}" if r["first_stamp_s"] is not None else "-"
        rows.append(
            (
                r["topic"],
                r["type"],
                str(r["count"]),
                f"{r['rate_hz']:.2f}",
                f"{r['span_s']:.2f}",
                stamp,
                "yes" if r["supported"] else "no (unsupported type)",
            )
        )
    widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
    for row in rows:
        click.echo("  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip())
    mp = info["mapping"]
    click.echo("\nproposed mapping (TOML; see docs/bags.md):\n")
    if mp.entries:
        click.echo(mp.to_toml())
        if not any(e.reference for e in mp.entries):
            click.echo("# no reference topic recognised: add a [reference] position = \"/topic\" entry")
    else:
        click.echo("# no topic of a supported type")
    if write_mapping:
        if not mp.entries:
            raise ReplayError(f"{path}: nothing to map, {write_mapping} not written")
        outfile.write(write_mapping, "--write-mapping", lambda tmp: Path(tmp).write_text(mp.to_toml()))
        click.echo(f"wrote {write_mapping}")


def export_outputs(
    run_dir, mcap_out=None, ros2_out=None, data_dir=None, run: int = 0, select=None, sigma=None, quiet: bool = False
) -> None:
    """Export one run of an evaluation directory (or of a campaign's configurations chosen by
    ``select``) as a Foxglove MCAP and/or a ROS 2 bag.

    Done by :func:`replay.outputs.exports.export_run` (which owns the targets' output sets); progress
    over the messages written goes to stderr (a bar on a terminal, a line every ~10 s otherwise), none
    if ``quiet``; a line per export on stdout.
    """
    from replay.outputs.exports import export_run

    for done in export_run(
        run_dir,
        mcap_out,
        ros2_out,
        data_dir=data_dir,
        run=run,
        select=select,
        sigma=sigma,
        progress=lambda kind: export_progress(kind, quiet),
    ):
        echo_export(done)


def export_progress(kind: str, quiet: bool):
    """The progress display of an export (``kind``: "mcap" or "ros2") over its messages."""
    from replay.outputs.exports import LABELS
    from replay.util.progress import Progress

    return Progress(0, quiet, label=LABELS[kind], unit="message")


def echo_export(done: dict) -> None:
    """The lines of one export written (:func:`replay.outputs.exports.export_run`'s item)."""
    target, slash, tracks = done["target"], "/" if done["kind"] == "ros2" else "", ", ".join(done["tracks"])
    click.echo(f"wrote {target}{slash} ({done['messages']} messages; run {done['run']}: {tracks})")
    click.echo(
        f"  open it in Foxglove: File > Open local file... > {Path(target).name} (3D panel: /replay/<track>/pose)"
        if slash == ""
        else f"  play it: ros2 bag play {target} (replay inspect {target} lists its topics)"
    )


@click.command("export")  # examples: replay.cli.examples
@click.argument("run_dir", type=click.Path())
@click.option(
    "--mcap",
    "mcap_out",
    default=None,
    type=click.Path(),
    help="Foxglove MCAP to write (poses, paths, frame transforms, covariance ellipsoids, errors, sensor "
    "data, the manifest as metadata); replaces only an MCAP replay wrote.",
)
@click.option(
    "--ros2-bag",
    "ros2_out",
    default=None,
    type=click.Path(),
    help="ROS 2 bag directory (MCAP storage, zstd chunks) with nav_msgs/Odometry per filter and the "
    "reference; replaces only a bag replay wrote.",
)
@click.option(
    "--tum",
    "tum_out",
    default=None,
    type=click.Path(),
    help="A `replay eval` output: write one row (--filter; default: its only smoother row, e.g. "
    "gtsam-batch) as a TUM track with its provenance header, the reference of another evaluation "
    "(replay eval ... --dataset-param reference=FILE).",
)
@click.option(
    "--run",
    "run",
    default=0,
    show_default=True,
    type=click.IntRange(min=0),
    help="Which Monte Carlo run to export (a recorded estimate has run 0 only, shown in every run).",
)
@click.option("--dataset", default=None, help="Campaign: the configurations of this dataset id (comma-separated list).")
@click.option("--task", default=None, help="Campaign: the configurations of this task.")
@click.option("--filter", "filter_", default=None, help="Campaign: only these filters (comma-separated).")
@click.option(
    "--config",
    default=None,
    help="Campaign: only the configurations whose hash (units/<hash>) starts with one of these (comma-separated).",
)
@click.option(
    "--sigma",
    default=None,
    type=click.FloatRange(min=0, min_open=True),
    help="Scale of the covariance ellipsoids: semi-axes of this many standard deviations.  [default: 3]",
)
@DATA_DIR
@click.option("--quiet", "-q", is_flag=True, help="No progress display and no notes (errors still print).")
def export_cmd(run_dir, mcap_out, ros2_out, tum_out, run, dataset, task, filter_, config, sigma, data_dir, quiet=False):
    """Export one run of a `replay eval` output directory, or of a campaign's result directory, for
    Foxglove (MCAP) or `ros2 bag play`.

    A campaign export holds the configurations that ran on the same measurements (one dataset and
    task); choose them with --dataset, --task, --filter and --config when it holds several.
    """
    if not (mcap_out or ros2_out or tum_out):
        raise ReplayError("export: give --mcap FILE, --ros2-bag DIR and/or --tum FILE")
    if quiet:  # the library's notes (logger "replay") down to warnings, as replay eval -q does
        import logging

        logging.getLogger("replay").setLevel(logging.WARNING)
    if tum_out:
        from replay.outputs.export_reference import write_reference

        n, line = write_reference(run_dir, tum_out, filter_, run=run, data_dir=data_dir)
        click.echo(f"wrote {tum_out} ({n} poses; reference: {line})")
        if not (mcap_out or ros2_out):
            return
        filter_ = None  # it chose the TUM row; the MCAP and bag hold every row of an eval output
    export_outputs(
        run_dir,
        mcap_out,
        ros2_out,
        data_dir=data_dir,
        run=run,
        sigma=sigma,
        quiet=quiet,
        select={"dataset": dataset, "task": task, "filter": filter_, "config": config},
    )
