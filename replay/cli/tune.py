"""``replay tune``: each filter at its best on training data, scored on held-out data."""

from __future__ import annotations

from pathlib import Path

import click

from replay.cli.run_options import DATA_DIR, MAPPING, run_option
from replay.cli.view_options import fault_option, with_views
from replay.util.errors import ReplayError


@click.command("tune")
@click.argument("dataset", required=False)
@click.option("--filters", "-f", default="ekf,ukf,pf", show_default=True, help="Comma-separated filters to tune.")
@click.option("--task", "-t", default=None, help="Task (default: the dataset's default task).")
@click.option(
    "--space",
    "space_file",
    default=None,
    type=click.Path(dir_okay=False),
    help="Search space TOML file: FILTER.PARAM = \"log[a,b]\" | [a,b] | [choices...].",
)
@click.option(
    "--param",
    "-p",
    "space_params",
    multiple=True,
    help="Search space entry FILTER.PARAM=SPEC or task.PARAM=SPEC, SPEC log[a,b], [a,b] or choice[v1,v2] (repeatable).",
)
@click.option("--trials", default=50, show_default=True, type=int, help="Trials per filter (the same for each).")
@click.option(
    "--objective",
    default="mean_rmse",
    show_default=True,
    help="mean_rmse, median_rmse, lost, nll, anees, or weighted:NAME=W,NAME=W.",
)
@click.option(
    "--train-segment",
    default=None,
    help="Train on this first fraction of DATASET's duration (e.g. 0.6), test on the rest.",
)
@click.option("--train", default=None, help="Training dataset ids, comma-separated (with --test).")
@click.option("--test", default=None, help="Test dataset ids, comma-separated (with --train).")
@click.option("--split", default=None, help="'seeds': simulated data, train on --seed, test on --seed + 1.")
@run_option("runs", "-n", default=20, extra=" Per configuration.")
@run_option("seed", "-s", extra=" Also the sampler's.")
@run_option("first")
@click.option("--rate", default=None, type=float, help="Dataset view: resample at this rate (Hz).")
@click.option("--window", default=None, help="Dataset view: START:END seconds, or #i:j samples.")
@fault_option
@click.option("--task-param", "task_params", multiple=True, help="Task parameter NAME=VALUE (repeatable).")
@click.option("--dataset-param", "dataset_params", multiple=True, help="Dataset parameter NAME=VALUE (repeatable).")
@click.option(
    "--out",
    "-o",
    required=True,
    type=click.Path(file_okay=False),
    help="Tune directory (study.db, units/, leaderboard.csv, tuned.toml); resumed when it exists.",
)
@DATA_DIR
@MAPPING
@click.option(
    "--workers",
    "-w",
    default=None,
    type=click.IntRange(1),
    help="Local worker processes for a trial's runs (default: in this process).",
)
@click.option("--dask-local", default=None, type=click.IntRange(1), help="Start a Dask LocalCluster of N workers.")
@click.option("--scheduler", default=None, help="Dask scheduler address, e.g. tcp://host:8786.")
@click.option("--allow-overlap", is_flag=True, help="Allow training and test data to overlap (flagged on every row).")
@click.option(
    "--wait",
    is_flag=True,
    help="If another replay tune is writing to --out, wait for it to finish instead of refusing.",
)
@click.option("--quiet", "-q", is_flag=True, help="No progress display.")
def tune_cmd(
    dataset,
    filters,
    task,
    space_file,
    space_params,
    trials,
    objective,
    train_segment,
    train,
    test,
    split,
    runs,
    seed,
    first,
    rate,
    window,
    fault,
    task_params,
    dataset_params,
    out,
    data_dir,
    mapping,
    workers,
    dask_local,
    scheduler,
    allow_overlap,
    wait,
    quiet,
):
    """Tune each filter's declared parameters on training data and score it on held-out data."""
    from replay.cli import params as cli_params
    from replay.cli.campaign import check_names
    from replay.data.registry import check_data_dir
    from replay.tune import check, run, space
    from replay.tune.write import board_notes, format_board, output_set

    if sum(x is not None for x in (workers, scheduler, dask_local)) > 1:
        raise ReplayError("give at most one of --workers, --scheduler, --dask-local")
    check_data_dir(data_dir, "--data-dir")
    entries = (space.entries_from_file(space_file) if space_file else []) + space.entries_from_cli(space_params)
    if not entries:
        raise ReplayError("no search space: give --space FILE.toml or --param FILTER.PARAM=SPEC")
    given = [data_dir, dataset if dataset and Path(dataset).exists() else None, space_file, mapping]
    output = output_set(out, given)
    output.rule(Path(out), out)  # its contents first: a foreign directory refused before the data is read
    t = check.prepare(
        check.TuneOptions(
            dataset=dataset,
            filters=filters.split(","),
            entries=entries,
            trials=trials,
            objective=objective,
            runs=runs,
            seed=seed,
            task=task,
            task_params=cli_params.task_params(task_params, task),
            dataset_params=with_views(
                cli_params.dataset_inputs(dataset_params, mapping), fault=fault
            ),  # as replay eval
            view={"rate": rate, "window": window},
            first=first,
            data_dir=data_dir,
            train_segment=train_segment,
            train=train,
            test=test,
            split=split,
            allow_overlap=allow_overlap,
        )
    )
    check_names(out, "--out")
    output.check()
    res = run.tune(t, out, workers=workers, scheduler=scheduler, dask_local=dask_local, quiet=quiet, wait=wait)
    click.echo(format_board(res["rows"]))
    for line in board_notes(res["rows"], res.get("failed")):
        click.echo(line)
    budget = res["budget"]
    same = len(set(budget.values())) == 1
    click.echo(
        f"budget: {next(iter(budget.values()))} trials per filter, the same for every filter"
        if same
        else "budget differs between filters: " + ", ".join(f"{k} {v} trials" for k, v in budget.items())
    )
    if t.split.overlap:
        click.echo("warning: training and test data overlap (--allow-overlap): test scores are not held out")
    click.echo("wrote " + ", ".join(str(p) for p in res["paths"].values()))
