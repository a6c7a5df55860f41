"""``replay convert SOURCE OUT``: a trajectory from any source ``replay score`` reads, written as TUM, KITTI,
EuRoC, CSV or MCAP (:mod:`replay.trajectory.convert`; evo_traj's ``--save_as_tum``). Registered in
:mod:`replay.cli.main`."""

from __future__ import annotations

from pathlib import Path

import click


@click.command("convert")
@click.argument("source")
@click.argument("out")
@click.option(
    "--format",
    "fmt",
    metavar="tum|kitti|euroc|csv|mcap",
    default=None,
    help="Output format (default: from OUT's extension: .tum/.txt TUM, .kitti, .csv plain CSV, .mcap). "
    "KITTI writes times.txt beside OUT (an existing times.txt with other stamps is refused unless --force).",
)
@click.option(
    "--in-format",
    "in_fmt",
    type=click.Choice(["tum", "kitti", "euroc", "csv"]),
    default=None,
    help="Format of a SOURCE file (default: from its header, extension and column count, as replay score).",
)
@click.option(
    "--kitti-times",
    type=click.Path(dir_okay=False),
    default=None,
    help="Stamps of KITTI SOURCE poses (default: times.txt beside them).",
)
@click.option("--columns", default=None, help="Columns of a plain CSV SOURCE, as replay score --columns.")
@click.option(
    "--time-unit", type=click.Choice(["s", "ms", "us", "ns"]), default=None, help="Unit of a CSV SOURCE's time column."
)
@click.option("--topic", default="/pose", show_default=True, help="MCAP output: the topic of the PoseStamped messages.")
@click.option("--frame-id", default="map", show_default=True, help="MCAP output: header.frame_id of the messages.")
@click.option(
    "--force",
    is_flag=True,
    help="KITTI: replace a times.txt beside OUT that holds other stamps (it re-times the poses it belonged to).",
)
def convert_cmd(source, out, fmt, in_fmt, kitti_times, columns, time_unit, topic, frame_id, force):
    """Write the trajectory SOURCE (a file, RECORDING:TOPIC or RECORDING:tf:PARENT,CHILD) to OUT."""
    from replay.trajectory import convert, io
    from replay.util import outfile
    from replay.util.files import refuse_overlap

    fmt = convert.fmt_of(out, fmt)
    times = Path(out).parent / "times.txt" if fmt == "kitti" else None
    inputs = [io.split(source)[0], Path(kitti_times) if kitti_times else None]
    for path, what in ((out, "OUT"), (times, "OUT's times.txt (KITTI)")):
        if path is not None:
            refuse_overlap(path, inputs, what)
            outfile.check(path, what)
    tr = io.load(source, fmt=in_fmt, kitti_times=kitti_times, columns=columns, time_unit=time_unit, exact=True)
    convert.check(tr, fmt)
    if times is not None and not force:
        convert.refuse_other_times(times, tr)
    if fmt == "mcap":
        outfile.write(out, "OUT", lambda tmp: convert.write_mcap(tmp, tr, topic=topic, frame_id=frame_id))
    else:
        if times is not None:
            outfile.write(times, "OUT's times.txt", lambda tmp: Path(tmp).write_text(convert.kitti_times(tr)))
        outfile.write(out, "OUT", lambda tmp: Path(tmp).write_text(convert.text(tr, fmt)))
    click.echo(
        f"{len(tr)} poses of {io.label(source)} -> {out} ({fmt}{', stamps in ' + str(times) if times else ''}"
        f"{', topic ' + topic if fmt == 'mcap' else ''})"
    )
