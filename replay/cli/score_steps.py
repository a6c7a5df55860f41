"""The steps of ``replay score`` (:mod:`replay.cli.score`): check the options before any file is read,
load the trajectories (each recording once), score and print each estimate as evo does, then write
the leaderboard, the results archive and the figures."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import click

from replay.util.errors import ReplayError

ALIGN_TITLES = {
    "none": "(not aligned)",
    "se3": "(with SE(3) Umeyama alignment)",
    "sim3": "(with Sim(3) Umeyama alignment)",
    "scale": "(scale corrected)",
    "yaw": "(with yaw-only (4-DoF) alignment)",
}
REL_TITLES = {
    "trans": "translation part",
    "rot": "rotation part",
    "full": "full transformation",
    "angle_deg": "rotation angle in degrees",
    "angle_rad": "rotation angle in radians",
    "point_distance": "point distance",
    "point_distance_error_ratio": "point distance error ratio",
}
DELTA_UNITS = {"f": "frames", "m": "m", "d": "deg", "r": "rad", "s": "s"}


def resolve_align(align, a_flag, s_flag) -> str:
    """``--align`` and evo's ``-a`` / ``-s`` / ``-as`` as one method (refused when they disagree)."""
    flags = "sim3" if a_flag and s_flag else "se3" if a_flag else "scale" if s_flag else None
    if align and flags and align != flags:
        given = "-as" if a_flag and s_flag else "-a" if a_flag else "-s"
        raise ReplayError(f"--align {align} and {given} ({flags}) disagree: give one")
    return align or flags or "none"


def block(title: str, stats: dict) -> str:
    return title + "\n\n" + "".join(f"{k:>10}\t{v:.6f}\n" for k, v in sorted(stats.items()))


def title(kind: str, rel: str, opts: dict) -> str:
    """evo's title of an APE or RPE block."""
    from replay.trajectory.pose_error import UNITS

    unit = UNITS[rel] or "unit-less"
    t = f"{kind} w.r.t. {REL_TITLES[rel]} ({unit})"
    if kind == "RPE":
        t += (
            f"\nfor delta = {opts['delta']:g} ({DELTA_UNITS[opts['delta_unit']]}) using "
            f"{'all' if opts['all_pairs'] else 'consecutive'} pairs"
        )
    if not (opts["align"] == "none" and opts["align_origin"]):
        t += "\n" + ALIGN_TITLES[opts["align"]]
    if opts["align"] != "none" and opts["n_to_align"]:
        t += f" (aligned poses: {opts['n_to_align']})"
    if opts["align_origin"]:
        t += "\n(with origin alignment)"
    return t


@dataclass
class ScoreRun:
    """``replay score``'s options once checked (:func:`checked`): ``options``, the record that decides
    the numbers (:class:`replay.trajectory.score_options.ScoreOptions`), and what is read and written."""

    options: object  # replay.trajectory.score_options.ScoreOptions
    reference: str
    estimates: list  # the ESTIMATE arguments
    sets: dict  # the trial sets (--trials), by name
    members: list  # their members: (name, set, trial, source)
    sources: list  # every estimate read: the arguments, then the trials' members
    fmt: str | None
    kitti_times: str | None
    columns: str | None
    time_unit: str | None
    out: str | None
    save_results: str | None
    plot_path: str | None
    plot_mode: str | None
    trial_plot: str | None
    names: list = field(default_factory=list)  # every source's name, once loaded (:func:`load`)


def checked(options: dict) -> ScoreRun:
    """The command's options, checked whole before any file is read (one line each), with what
    follows from them: the alignment method, the parsed lengths, the relations, the trial sets and
    every source to read."""
    from replay.trajectory import trials as trial_sets
    from replay.trajectory import io
    from replay.trajectory.plot import FORMATS as PLOT_FORMATS
    from replay.trajectory.plot import paths as plot_paths
    from replay.trajectory.score_options import PREPARE, ScoreOptions
    from replay.util import outfile
    from replay.util.files import refuse_overlap

    o = dict(options)
    if o["p_flag"]:
        raise ReplayError(
            "-p: replay never opens a window; write the figures with --plot FILE (png, pdf, svg; evo's --save_plot)"
        )
    if o["save_as"]:
        raise ReplayError(
            "--save_as_tum/--save_as_kitti/--save_as_bag: replay score writes no trajectories; convert "
            "one with replay convert SOURCE OUT.tum (.kitti, .csv, .mcap; --format euroc)"
        )
    align = resolve_align(o["align"], o["a_flag"], o["s_flag"])
    if o["lengths"] is not None:
        from replay.trajectory import lengths as by_length

        o["lengths"] = by_length.parse(o["lengths"])  # refused before any file is read
    o["relations"] = list(dict.fromkeys(o["relations"] or ["trans"]))
    numbers = ScoreOptions(align=align, **{k: o[k] for k in SCORE_FIELDS}, **{k: o[k] for k in PREPARE})
    if "point_distance_error_ratio" in numbers.relations and not numbers.want_rpe:
        raise ReplayError("-r point_distance_error_ratio is an RPE relation: add --rpe")
    sets = trial_sets.parse(o["trial_specs"])
    trial_sets.not_reference(sets, o["reference"])
    if not o["estimates"] and not sets:
        raise ReplayError("replay score REFERENCE ESTIMATE...: no estimate (give estimates, or --trials GLOB)")
    members = trial_sets.members(sets)
    sources = [*o["estimates"], *(m[3] for m in members)]
    o = ScoreRun(numbers, sets=sets, members=members, sources=sources, **{k: o[k] for k in IO_FIELDS})
    inputs = [io.split(s)[0] for s in (o.reference, *o.sources)] + ([Path(o.kitti_times)] if o.kitti_times else [])
    if o.trial_plot and not o.sets:
        raise ReplayError("--trials-plot: boxplots of trials: give --trials [NAME=]GLOB")
    plots = list(plot_paths(o.plot_path).values()) if o.plot_path else []
    for path, what, suffixes in (
        (o.out, "--out", None),
        *((p, "--plot", PLOT_FORMATS) for p in plots),
        (o.trial_plot, "--trials-plot", PLOT_FORMATS),
    ):
        if path:
            refuse_overlap(path, inputs, what)
            outfile.check(path, what, suffixes)
    if o.save_results:
        from replay.trajectory import archive

        archive.check(o.save_results, inputs)
    return o


def load(o: ScoreRun) -> tuple:
    """(the reference, the estimates) as trajectories, named; each recording read once."""
    from replay.trajectory.score_result import estimate_name
    from replay.trajectory import io

    columns, columns_of = io.split_columns(o.columns, [o.reference, *o.sources])
    taken = set()
    o.names = [estimate_name(spec, taken) for spec in o.estimates] + [m[0] for m in o.members]
    ref, *ests = io.load_all(
        [o.reference, *o.sources],
        names=[estimate_name(o.reference, set()), *o.names],
        columns_of=columns_of,
        fmt=o.fmt,
        kitti_times=o.kitti_times,
        columns=columns,
        time_unit=o.time_unit,
    )
    return ref, ests


# the fields of ScoreOptions taken from the command's options as they are (besides ``align``, resolved
# from --align/-a/-s, and evo's trajectory options, replay.trajectory.score_options.PREPARE)
SCORE_FIELDS = (
    "n_to_align",
    "align_origin",
    "t_max_diff",
    "t_offset",
    "relations",
    "rpe",
    "delta",
    "delta_unit",
    "delta_tol",
    "all_pairs",
    "pairs_from_reference",
    "lengths",
    "lengths_method",
    "lost_threshold",
    "lost_steps",
)
# ScoreRun's fields taken from the command's options as they are
IO_FIELDS = (
    "reference",
    "estimates",
    "fmt",
    "kitti_times",
    "columns",
    "time_unit",
    "out",
    "save_results",
    "plot_path",
    "plot_mode",
    "trial_plot",
)


def score_all(o: ScoreRun, ref, ests):
    """Every estimate scored and printed as evo prints it (trials in their table): a ScoreResult."""
    from replay.trajectory import trials as trial_sets
    from replay.trajectory.score_result import ScoreResult, leaderboard_row
    from replay.trajectory import io, score

    n = o.options
    opts, scores, summary, first = n.settings(), {}, [], len(o.estimates)
    for k, (spec, name, est) in enumerate(zip(o.sources, o.names, ests)):
        with trial_sets.naming(o.members[k - first] if k >= first else None):
            s = score(ref, est, **opts)
        scores[name] = s
        click.echo(
            f"{name} vs {ref.name}: {len(s.reference)} of {len(est)} poses matched (reference: {len(ref)} "
            f"poses; t_max_diff {n.t_max_diff:g} s{f', t_offset {n.t_offset:g} s' if n.t_offset else ''})"
            + (f"; scale {s.transform[2]:.6f}" if n.align in ("sim3", "scale") else "")
        )
        row = leaderboard_row(
            s,
            reference=o.reference,
            dataset=io.label(o.reference),
            estimate=spec,
            name=name,
            settings=opts,
            lost_threshold=n.lost_threshold,
            lost_steps=n.lost_steps,
        )
        summary.append(row)
        if k >= first:  # a trial: its numbers are in the trials table below
            trial_sets.mark(row, *o.members[k - first][1:])
            continue
        _print_score(o, s, opts)
    result = ScoreResult(ref, scores, summary, opts)
    _print_tables(o, result, summary)
    return result


def _print_score(o: ScoreRun, s, opts: dict) -> None:
    for rel in s.ape:
        click.echo(block(title("APE", rel, opts), s.stats("ape", rel)))
    for rel in s.rpe:
        click.echo(block(title("RPE", rel, opts), s.stats("rpe", rel)))
    if s.lengths:
        from replay.trajectory import lengths as by_length

        click.echo(by_length.table(s.lengths, o.options.lengths_method))


def _print_tables(o: ScoreRun, result, summary: list) -> None:
    """The trial sets' tables, and with several estimates one line each (evo_res's table)."""
    from replay.trajectory import trials as trial_sets

    n = o.options
    rows = result.output_rows()
    for name in o.sets:
        mine = [r for r in rows if r["filter"] == f"recorded:{name}" and "trial" in r]
        click.echo(trial_sets.table(name, mine, n.relations, n.want_rpe))
    plain = [row for row in summary if "trial" not in row]
    if len(plain) > 1:
        rel = n.relations[0]
        rpe = f" {'RPE ' + rel + ' rmse':>22}" if n.want_rpe else ""
        click.echo(f"{'estimate':<24} {'matched':>8} {'APE ' + rel + ' rmse':>22}" + rpe)
        for row in plain:
            click.echo(
                f"{row['filter'][9:]:<24} {row['matched']:>8} {row.get(f'ape_{rel}_rmse', math.nan):>22.6f}"
                + (f" {row.get(f'rpe_{rel}_rmse', math.nan):>22.6f}" if n.want_rpe else "")
            )


def write(o: ScoreRun, result) -> None:
    """The leaderboard (``-o``), the results archive, the figures and the trials' boxplots."""
    from replay.scoring.summary import columns as leaderboard_columns
    from replay.util import outfile
    from replay.util.files import write_csv

    rows = result.output_rows()
    if o.out:
        outfile.write(o.out, "--out", lambda tmp: write_csv(rows, tmp, leaderboard_columns(rows)))
        click.echo(f"leaderboard: {o.out}")
    if o.save_results:
        from replay.trajectory import archive

        archive.save(result, o.save_results, reference=o.reference)
        click.echo(f"results: {o.save_results} (replay res {o.save_results})")
    if o.plot_path:
        from replay.trajectory import plot

        written, removed = plot.write(
            o.plot_path, result.reference, result.scores, relation=o.options.relations[0], mode=o.plot_mode
        )
        click.echo(
            f"plot: {', '.join(map(str, written))}"
            + (f" (removed the earlier {', '.join(map(str, removed))})" if removed else "")
        )
    if o.trial_plot:
        from replay.trajectory import boxplots

        boxplots.write(o.trial_plot, result)
        click.echo(f"trials plot: {o.trial_plot}")
