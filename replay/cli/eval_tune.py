"""``replay eval DATASET --tune N``: every filter at its best, with intervals that include tuning.

Each filter's declared noise (:func:`replay.tune.repeat.default_space`, or ``--tune-space FILE.toml``) is
tuned with ``N`` trials on the training part (``--train-segment``, default 0.6 of a recording; a
simulation's seed split), ``--tune-repeats`` times with other sampler seeds (:mod:`replay.tune.repeat`,
the ``replay tune`` machinery), and scored on the held-out rest. Prints and writes (``OUT/tuned.csv``,
``OUT/ranking.csv``) the default and tuned rows with their intervals over tunes x runs, and the ranking;
with ``--tune-grid G``, the optimiser's distance from a grid optimum (:mod:`replay.tune.grid_check`).
"""

from __future__ import annotations

from pathlib import Path

import click

from replay.cli.run_options import Existing
from replay.util.errors import ReplayError

TUNE_OPTIONS = (
    click.option(
        "--tune",
        "tune_trials",
        default=None,
        type=click.IntRange(1),
        help="Tune each filter's declared noise with this many trials per tune on the training part and score "
        "the held-out rest (--tune-repeats tunes; needs --out).",
    ),
    click.option(
        "--tune-repeats",
        default=None,
        type=int,
        help="With --tune: tunes per filter, each with other sampler seeds (default 3); the intervals cover them.",
    ),
    click.option(
        "--train-segment",
        default=None,
        help="With --tune: the first fraction of a recording tuned on (default 0.6); the rest is scored.",
    ),
    click.option(
        "--tune-objective",
        default=None,
        help="With --tune: the objective, as replay tune --objective takes it (default mean_rmse).",
    ),
    click.option(
        "--tune-grid",
        default=None,
        type=int,
        help="With --tune: also score a grid of G points per searched parameter on the first tune's training "
        "data and report the tuned values' distance from its optimum (where a grid is cheap: at most 400 points).",
    ),
    click.option(
        "--tune-space",
        default=None,
        type=Existing(dir_okay=False),
        help="With --tune: a search space file as replay tune --space takes (default: q_scale, r_scale, "
        "and a particle filter's n_particles).",
    ),
)


def tune_options(f):
    for opt in reversed(TUNE_OPTIONS):
        f = opt(f)
    return f


def data_options(o: dict) -> tuple[dict, dict]:
    """(task parameters, dataset parameters) of ``replay eval``'s options ``o`` (its arguments), with or
    without ``--tune``: ``--data-dir`` checked, ``--task-param``, ``--dataset-param``, ``--mapping`` and
    the views (``--rate``, ``--window``, ``--segment``, ``--fault``)."""
    from replay.cli import params as cli_params
    from replay.cli.view_options import with_views
    from replay.data.registry import check_data_dir

    check_data_dir(o["data_dir"], "--data-dir")
    views = (o["rate"], o["window"], o["segment"], o["fault"])
    dparams = with_views(cli_params.dataset_inputs(o["dataset_params"], o["mapping"]), *views)
    return cli_params.task_params(o["task_params"], o["task"]), dparams


def from_cli(dataset, o: dict):
    """``replay eval``'s options (``o``: its arguments) with ``--tune``."""
    if o["tune_trials"] is None:
        raise ReplayError(
            "--tune-repeats, --train-segment, --tune-space, --tune-objective and --tune-grid go with --tune N"
        )
    given = dict(
        params=o["params"], tuned=o["tuned"], mcap=o["mcap_out"], ros2_bag=o["ros2_out"], baseline=o["baseline"]
    )
    bad = [k for k, v in given.items() if v]
    if bad:
        raise ReplayError(
            "--tune: " + ", ".join("--" + k.replace("_", "-") for k in bad) + " not taken with --tune "
            "(it tunes the filters' declared noise; give a search space with --tune-space)"
        )
    tparams, dparams = data_options(o)
    run(
        dataset,
        trials=o["tune_trials"],
        repeats=o["tune_repeats"],
        train_segment=o["train_segment"],
        space_file=o["tune_space"],
        grid=o["tune_grid"],
        objective=o["tune_objective"] or "mean_rmse",
        filters=o["filters"],
        task=o["task"],
        task_params=tparams,
        dataset_params=dparams,
        out=o["out"],
        runs=o["runs"],
        seed=o["seed"],
        first=o["first"],
        data_dir=o["data_dir"],
        alignment=o["alignment"],
        quiet=o["quiet"],
    )


def run(
    dataset,
    *,
    trials,
    repeats,
    train_segment,
    space_file,
    grid,
    objective,
    filters,
    task,
    task_params,
    dataset_params,
    out,
    **o,
):
    """Check, tune ``repeats`` times, print and write the rows and the ranking (module docstring)."""
    from replay.data.dataset_ref import simulated
    from replay.tune import check, repeat, space
    from replay.util.files import write_csv

    if out is None:
        raise ReplayError("--tune: give --out DIR (the tunes' directory: tune-K/, units/, tuned.csv, ranking.csv)")
    from replay.tune.write import repeats_set

    mapping = (dataset_params or {}).get("mapping")  # --out before any tune: never onto an input, ours resumed
    repeats_set(out, [o["data_dir"], dataset if Path(dataset).exists() else None, space_file, mapping]).check()
    names = [f.strip() for f in filters.split(",") if f.strip() and f.strip() != "measurements"]
    entries = space.entries_from_file(space_file) if space_file else repeat.default_space(names)
    sim = simulated(dataset)
    if sim and train_segment is not None:
        raise ReplayError("--train-segment: a simulation is tuned on one seed and scored on another (no segment)")
    t = check.prepare(
        check.TuneOptions(
            dataset=dataset,
            filters=names,
            entries=entries,
            trials=trials,
            objective=objective,
            runs=o["runs"],
            seed=o["seed"],
            task=task,
            task_params=task_params,
            dataset_params=dataset_params,
            first=o["first"],
            data_dir=o["data_dir"],
            train_segment=None if sim else (train_segment or "0.6"),
            split="seeds" if sim else None,
            alignment=o["alignment"],
        )
    )
    res = repeat.run_repeats(t, Path(out), repeat.REPEATS if repeats is None else repeats, quiet=o["quiet"])
    click.echo(
        f"{dataset}  task={t.task}  tuned on {t.split.tuned_on}, tested on {t.split.tested_on} "
        f"(tune k: every seed + {repeat.STRIDE} k); {trials} trials per tune"
    )
    click.echo(repeat.format_rows(res["rows"]))
    lines = repeat.ranking(res)
    for line in lines:
        click.echo(line)
    if grid is not None:  # the optimiser's distance from a grid optimum (replay.tune.grid_check)
        from replay.tune import grid_check

        res["grid"] = grid_check.distances(t, Path(out), res["tunes"][0]["rows"], grid)
        for line in grid_check.format_rows(res["grid"]):
            click.echo(line)
    write_csv(res["rows"], Path(out) / "tuned.csv", list(res["rows"][0]))
    write_csv(res["pairs"], Path(out) / "ranking.csv", ["a", "b", "difference", "ci95", "different"])
    click.echo(f"wrote {Path(out) / 'tuned.csv'}, {Path(out) / 'ranking.csv'}")
    return res
