"""`replay datasets ...`: list, describe and download the registered datasets.

Errors are raised as ReplayError; the top-level `replay` command prints them on
one line and exits with status 2.
"""

from __future__ import annotations

import click

from replay.cli.run_options import MAPPING
from replay.cli.view_options import view_options, with_views
from replay.data import dataset_ref, registry
from replay.data.fetch import DEFAULT_DEADLINE
from replay.data.fetch import fetch as fetch_dataset
from replay.util.errors import ReplayError


# `replay datasets` inspects: a --data-dir that does not exist is only a place where the file is not
# (the eval-family commands refuse it: replay.cli.run_options.DATA_DIR)
DATA_DIR = click.option(
    "--data-dir",
    type=click.Path(file_okay=False),
    default=None,
    help="Look here first for dataset files (then $REPLAY_DATA_DIR, then the cache).",
)


@click.group("datasets")
def datasets():
    """List, describe and download datasets."""


def _where(ds, data_dir) -> str:
    if ds.kind == "sim":
        return "generated"
    path = registry.locate(ds, data_dir)
    return str(path) if path else "missing"


def _short(text: str, width: int = 60) -> str:
    return text if len(text) <= width else text[: width - 1] + "…"


@datasets.command("list")
@DATA_DIR
def list_cmd(data_dir):
    """One line per dataset: where it is, rows, whether its checksum is known."""
    rows = [("id", "present", "rows", "sha256", "description")]
    for ds in registry.all_datasets().values():
        known = "-" if ds.kind == "sim" else ("known" if ds.sha256 else "unknown")
        rows.append((ds.id, _where(ds, data_dir), str(ds.rows or "-"), known, _short(ds.description)))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    for r in rows:
        click.echo("  ".join(c.ljust(w) for c, w in zip(r, widths)) + "  " + r[4])


@datasets.command("info")
@click.argument("dataset")
@DATA_DIR
@click.option("--adapter", default=None, help="Adapter for a plain file (default: chosen from the file).")
@MAPPING
@click.option(
    "--dataset-param",
    "dataset_params",
    multiple=True,
    help="Dataset parameter NAME=VALUE (repeatable; as for `replay eval`).",
)
@view_options
def info_cmd(
    dataset, data_dir, adapter=None, mapping=None, dataset_params=(), rate=None, window=None, segment=None, fault=()
):
    """Manifest fields, location and, when present, what loading it gives.

    DATASET is what `replay eval` takes: a registered id, or a file (a CSV, a ROS 1 .bag, a
    ROS 2 bag directory, an .mcap with --mapping), read the same way."""
    from replay.cli.params import dataset_inputs
    from replay.run.pipeline import load_frame

    ref = dataset_ref.resolve(dataset, adapter)
    dparams = registry.check_params(
        ref.target, with_views(dataset_inputs(dataset_params, mapping), rate, window, segment, fault), adapter=adapter
    )
    config = {"dataset": dataset, "dataset_params": dparams, "first": None, "seed": 0, "adapter": adapter}
    if ref.is_path:
        frame = load_frame(config, 0, data_dir, ds=None)  # as `replay eval` reads it
        click.echo(f"{'path:':15s} {dataset}")
        _describe(frame)
        return
    ds = ref.entry
    for key, value in ds.__dict__.items():
        if value not in (None, ""):
            click.echo(f"{key + ':':15s} {value}")
    where = _where(ds, data_dir)
    click.echo(f"{'location:':15s} {where}")
    if ds.kind == "file" and not ds.sha256:
        click.echo(f"{'checksum:':15s} not registered upstream (a download is accepted only after a content check)")
    if where == "missing":
        roots = ", ".join(str(r) for r in registry.search_roots(data_dir))
        click.echo(f"{'searched:':15s} {roots}")
        click.echo(f"run `replay datasets fetch {ds.id}` or pass --data-dir")
        return
    _describe(load_frame(config, 0, data_dir))


def _describe(frame) -> None:
    """What loading gave: the frame's summary, the adapter's report, its records and the metadata."""
    click.echo("summary:")
    for line in frame.summary():
        click.echo(f"  {line}")
    lines = frame.report.lines()
    click.echo("report:" if lines else "report: nothing dropped, repaired or flagged")
    for line in lines:
        click.echo(f"  {line}")
    if frame.roles is not None:  # the sensor inputs a task may use (replay.roles.SensorInput)
        click.echo("roles:" if frame.roles else "roles: no sensor input")
        for i in frame.roles:
            chans = ", ".join(f"{f} {c}" for f, c in i.channels.items())
            m = i.recorded_mount
            mount = f"; /tf_static {m.parent} -> {m.child}" if m else ""
            click.echo(f"  {i.role}: {i.entry} = {i.source} ({chans}){mount}")
    sim = frame.simulation
    if sim is not None:  # the simulator's validated parameters (replay.frame.Simulation)
        rec = sim.as_meta()
        step = "" if sim.dt is None else f", step {sim.dt:g} s"
        click.echo(f"simulation: {sim.generator}{step}")
        if sim.initial_state is not None:
            start = ", ".join(f"{n} = {x:g}" for n, x in zip(sim.state, sim.initial_state))
            click.echo(f"  initial state: {_short(start, 100)}")
        for key, value in rec["params"].items():
            click.echo(f"  {key}: {_short(str(value), 100)}")
    for key, value in {k: v for k, v in frame.records().items() if k != "simulation"}.items():
        click.echo(f"{key}: {_short(str(value), 100)}")
    click.echo("meta:")
    for key, value in frame.meta.items():
        click.echo(f"  {key}: {_short(str(value), 100)}")


@datasets.command("fetch")
@click.argument("dataset_ids", nargs=-1)
@click.option(
    "--dest",
    type=click.Path(file_okay=False),
    default=None,
    help="Download into this directory (default: the user cache).",
)
@click.option("--all", "fetch_all", is_flag=True, help="Fetch every downloadable dataset.")
@click.option(
    "--force",
    is_flag=True,
    help="Download again even if present; the copy is replaced only once the new one passed every check.",
)
@click.option(
    "--deadline",
    type=float,
    default=DEFAULT_DEADLINE,
    show_default=True,
    help="Seconds allowed for each whole download.",
)
@click.option("--quiet", "-q", is_flag=True, help="No progress display (results and errors still print).")
def fetch_cmd(dataset_ids, dest, fetch_all, force, deadline, quiet=False):
    """Download datasets, checked by size and sha256 where registered upstream, else by content.

    Nothing reaches its final name before it passed its checks; a failed download leaves
    what was there before."""
    if fetch_all:
        chosen = [ds for ds in registry.all_datasets().values() if ds.kind == "file"]
    elif dataset_ids:
        chosen = [registry.get(i) for i in dataset_ids]
    else:
        raise ReplayError("give dataset ids to fetch, or --all")
    if len(chosen) == 1:
        click.echo(_fetch_one(chosen[0], dest, deadline, force, quiet).message)
        return
    failed = []
    for ds in chosen:
        try:
            click.echo(_fetch_one(ds, dest, deadline, force, quiet).message)
        except ReplayError as e:
            click.echo(f"failed: {e}")  # stdout: the one line on stderr is the summary below
            failed.append(ds.id)
    if failed:
        raise ReplayError(f"{len(failed)} of {len(chosen)} downloads failed: {', '.join(failed)}")


def _fetch_one(ds, dest, deadline, force, quiet):
    """One download with a progress bar in kilobytes (when its size is known)."""
    from replay.util.progress import Progress

    progress = Progress(0, quiet, label=f"fetch {ds.id}", unit="kilobyte")
    try:
        return fetch_dataset(ds, dest, deadline=deadline, force=force, progress=progress)
    finally:
        progress.close()


@datasets.command("make")
@click.argument("dataset_id")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False), help="File to write.")
@click.option("--seed", "-s", default=0, show_default=True, type=int, help="Seed of the generator.")
@click.option(
    "--param", "-p", "params", multiple=True, help="Generator parameter NAME=VALUE (value parsed as JSON), repeatable."
)
def make_cmd(dataset_id, out, seed, params):
    """Write one generated log of a simulated dataset as a file (e.g. sim/lake-depth as a lake-trial CSV)."""
    from importlib import import_module

    import numpy as np

    from replay.cli.params import dataset_params

    ds = registry.get(dataset_id)
    if ds.kind != "sim":
        raise ReplayError(f"{ds.id} is a recording, not a generator: `replay datasets fetch {ds.id}`")
    module = import_module(ds.generator.split(":")[0])
    writer = getattr(module, "write_example", None)
    if writer is None:
        raise ReplayError(f"{ds.id}: its generator has no file format to write (no write_example)")
    frame = writer(out, np.random.default_rng(seed), **dataset_params(params, ds, option="--param"))
    click.echo(f"wrote {out}: {len(frame)} samples, seed {seed} (synthetic, {ds.id})")
