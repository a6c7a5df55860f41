"""`replay inspect FILE` and `replay export RUN_DIR`: ROS bags / MCAP in and out.

Errors are raised as ReplayError; the top-level `replay` command prints them on
one line and exits with status 2.
"""
from __future__ import annotations

from pathlib import Path

import click

from replay.util.errors import ReplayError


@click.command("inspect")
@click.argument("path", type=click.Path())
@click.option("--write-mapping", default=None, type=click.Path(dir_okay=False),
              help="Write the proposed mapping to this TOML file.")
def inspect_cmd(path, write_mapping):
    """List the topics of a bag or MCAP (type, count, rate, span) and propose a topic mapping."""
    from replay.adapters.bags import inspect

    info = inspect(path)
    click.echo(f"{info['path']}  format={info['format']}  messages={info['messages']}  "
               f"span={info['span_s']:.3f} s")
    if info["truncated"]:
        click.echo(f"TRUNCATED: {info['truncated']} (counts are what could be read)")
    head = ("topic", "type", "count", "rate Hz", "span s", "first stamp s", "mapped")
    rows = [head]
    for r in info["topics"]:
        stamp = f"{r['first_stamp_s']:.3f}" if r["first_stamp_s"] is not None else "-"
        rows.append((r["topic"], r["type"], str(r["count"]), f"{r['rate_hz']:.2f}", f"{r['span_s']:.2f}",
                     stamp, "yes" if r["supported"] else "no (unsupported type)"))
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
        Path(write_mapping).write_text(mp.to_toml())
        click.echo(f"wrote {write_mapping}")


def export_outputs(run_dir, mcap_out=None, ros2_out=None, data_dir=None) -> None:
    """Export an evaluation directory as a Foxglove MCAP and/or a ROS 2 bag."""
    if mcap_out:
        from replay.outputs.export_mcap import export_run

        n = export_run(run_dir, mcap_out, data_dir=data_dir)
        click.echo(f"wrote {mcap_out} ({n} messages)")
    if ros2_out:
        from replay.outputs.export_ros2 import export_run_ros2

        n = export_run_ros2(run_dir, ros2_out, data_dir=data_dir)
        click.echo(f"wrote {ros2_out}/ ({n} messages)")


@click.command("export")
@click.argument("run_dir", type=click.Path(exists=True, file_okay=False))
@click.option("--mcap", "mcap_out", default=None, type=click.Path(dir_okay=False),
              help="Foxglove MCAP to write (poses, paths, errors, sensor data).")
@click.option("--ros2-bag", "ros2_out", default=None, type=click.Path(file_okay=False),
              help="ROS 2 bag directory (MCAP storage) with nav_msgs/Odometry per filter and the reference.")
@click.option("--data-dir", default=None, type=click.Path(), help="Where to look for dataset files first.")
def export_cmd(run_dir, mcap_out, ros2_out, data_dir):
    """Export a `replay eval` output directory for Foxglove (MCAP) or `ros2 bag play`."""
    if not (mcap_out or ros2_out):
        raise ReplayError("export: give --mcap FILE and/or --ros2-bag DIR")
    export_outputs(run_dir, mcap_out, ros2_out, data_dir=data_dir)
