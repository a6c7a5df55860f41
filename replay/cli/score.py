"""``replay score REFERENCE ESTIMATE...``: score recorded trajectories as evo_ape / evo_rpe do.

Registered in :mod:`replay.cli.main` (``main.add_command(score_cmd)``). The numbers come from
:mod:`replay.trajectory`; the CSV has the leaderboard schema of :mod:`replay.scoring.summary`.
"""
from __future__ import annotations

import math
from pathlib import Path

import click

from replay.util.errors import ReplayError

ALIGN_TITLES = {"none": "(not aligned)", "se3": "(with SE(3) Umeyama alignment)",
                "sim3": "(with Sim(3) Umeyama alignment)", "scale": "(scale corrected)",
                "yaw": "(with yaw-only (4-DoF) alignment)"}
REL_TITLES = {"trans": "translation part", "rot": "rotation part", "full": "full transformation",
              "angle_deg": "rotation angle in degrees", "angle_rad": "rotation angle in radians",
              "point_distance": "point distance", "point_distance_error_ratio": "point distance error ratio"}
DELTA_UNITS = {"f": "frames", "m": "m", "d": "deg", "r": "rad", "s": "s"}


def _resolve_align(align, a_flag, s_flag) -> str:
    flags = "sim3" if a_flag and s_flag else "se3" if a_flag else "scale" if s_flag else None
    if align and flags and align != flags:
        given = "-as" if a_flag and s_flag else "-a" if a_flag else "-s"
        raise ReplayError(f"--align {align} and {given} ({flags}) disagree: give one")
    return align or flags or "none"


def _block(title: str, stats: dict) -> str:
    return title + "\n\n" + "".join(f"{k:>10}\t{v:.6f}\n" for k, v in sorted(stats.items()))


def _title(kind: str, rel: str, opts: dict) -> str:
    from replay.trajectory.pose_error import UNITS

    unit = UNITS[rel] or "unit-less"
    t = f"{kind} w.r.t. {REL_TITLES[rel]} ({unit})"
    if kind == "RPE":
        t += (f"\nfor delta = {opts['delta']:g} ({DELTA_UNITS[opts['delta_unit']]}) using "
              f"{'all' if opts['all_pairs'] else 'consecutive'} pairs")
    if not (opts["align"] == "none" and opts["align_origin"]):
        t += "\n" + ALIGN_TITLES[opts["align"]]
    if opts["align"] != "none" and opts["n_to_align"]:
        t += f" (aligned poses: {opts['n_to_align']})"
    if opts["align_origin"]:
        t += "\n(with origin alignment)"
    return t


@click.command("score")
@click.argument("reference")
@click.argument("estimates", nargs=-1)
@click.option("--align", type=click.Choice(["none", "yaw", "se3", "sim3", "scale"]), default=None,
              help="Alignment of each estimate onto the reference: none (default, as evo), yaw (4-DoF), se3, "
                   "sim3, scale (scale only).")
@click.option("-a", "a_flag", is_flag=True, help="evo's -a: SE(3) alignment (-as: Sim(3)).")
@click.option("-s", "--correct-scale", "--correct_scale", "s_flag", is_flag=True,
              help="evo's -s: correct the scale (alone: scale only; with -a: Sim(3)).")
@click.option("--n-to-align", "--n_to_align", "n_to_align", type=click.IntRange(1), default=None,
              help="Fit the alignment on the first N matched poses only (default: all).")
@click.option("--align-origin", "--align_origin", "align_origin", is_flag=True,
              help="Move each estimate so that its first pose is the reference's first pose.")
@click.option("--t-max-diff", "--t_max_diff", "t_max_diff", type=click.FloatRange(0), default=0.01,
              show_default=True, help="Largest stamp difference (s) of an associated pose pair.")
@click.option("--t-offset", "--t_offset", "t_offset", type=float, default=0.0, show_default=True,
              help="Constant offset (s) added to the estimates' stamps before association.")
@click.option("-r", "--pose-relation", "--pose_relation", "relations", multiple=True,
              type=click.Choice(["trans", "rot", "full", "angle_deg", "angle_rad", "point_distance",
                                 "point_distance_error_ratio", "trans_part", "rot_part"]),
              help="Pose relation (repeatable; default trans): evo's -r.")
@click.option("--rpe", is_flag=True, help="Also compute the RPE (implied by --delta).")
@click.option("-d", "--delta", type=click.FloatRange(0, min_open=True), default=None,
              help="RPE pose distance (default 1) in --delta-unit.")
@click.option("-u", "--delta-unit", "--delta_unit", "delta_unit", type=click.Choice(["f", "m", "d", "r", "s"]),
              default="f", show_default=True, help="f frames, m metres, d degrees, r radians, s seconds.")
@click.option("-t", "--delta-tol", "--delta_tol", "delta_tol", type=click.FloatRange(0), default=0.1,
              show_default=True, help="Relative delta tolerance of --all-pairs (m, d, r, s).")
@click.option("--all-pairs", "--all_pairs", "all_pairs", is_flag=True,
              help="RPE over all pairs at the delta instead of consecutive ones.")
@click.option("--pairs-from-reference", "--pairs_from_reference", "pairs_from_reference", is_flag=True,
              help="Choose the RPE pairs on the reference instead of the estimate.")
@click.option("--lengths", "lengths", default=None,
              help="Relative errors over sub-trajectory lengths, rpg_trajectory_evaluation / KITTI style: "
                   "10%,20%,30%,40%,50% of the reference's path length, or metres (100,200,...,800).")
@click.option("--lengths-method", "--lengths_method", "lengths_method", type=click.Choice(["rpg", "kitti"]),
              default="rpg", show_default=True,
              help="Sub-trajectories of --lengths: rpg (every start, end nearest to the length) or kitti "
                   "(every 10th start, first end beyond the length).")
@click.option("--sync-method", "--sync_method", "sync_method", type=click.Choice(["nearest", "interpolation"]),
              default="nearest", show_default=True,
              help="Association: the nearest stamp (evo's nearest_time), or interpolation: the denser trajectory "
                   "resampled at the other's matched stamps (evo's --sync_method interpolation).")
@click.option("--t-start", "--t_start", "t_start", type=float, default=None,
              help="Score only poses stamped at or after this (s; the estimate's stamps with --t-offset).")
@click.option("--t-end", "--t_end", "t_end", type=float, default=None, help="... and at or before this (s).")
@click.option("--downsample", type=click.IntRange(2), default=None,
              help="Keep N matched pose pairs, evenly spaced (evo's --downsample).")
@click.option("--motion-filter", "--motion_filter", "motion_filter", type=(float, float), default=None,
              help="DIST ANGLE: keep a pair when the reference moved DIST m or turned ANGLE deg since the last kept "
                   "one (evo's --motion_filter).")
@click.option("--project-to-plane", "--project_to_plane", "project_to_plane", type=click.Choice(["xy", "xz", "yz"]),
              default=None, help="Project both trajectories onto this plane after the alignment (evo's "
                                 "--project_to_plane).")
@click.option("--format", "fmt", type=click.Choice(["tum", "kitti", "euroc", "csv"]), default=None,
              help="Format of the trajectory files (default: from the header's column names, else the "
                   "extension and the column count; a CSV whose order they cannot tell is refused).")
@click.option("--kitti-times", type=click.Path(dir_okay=False), default=None,
              help="Stamps of KITTI poses, one per line (default: times.txt beside them).")
@click.option("--columns", multiple=True,
              help="Columns of a plain CSV, e.g. t=time,x=px,y=py,z=pz,qx=qx,qy=qy,qz=qz,qw=qw (or roll/pitch/yaw); "
                   "FILE=t=time,... for one file only (repeatable), e.g. a CSV estimate against a TUM reference.")
@click.option("--time-unit", type=click.Choice(["s", "ms", "us", "ns"]), default=None,
              help="Unit of the CSV time column (default: the unit its header names, else the one in which "
                   "the stamps are Unix time, else s).")
@click.option("--lost-threshold", type=click.FloatRange(0, min_open=True), default=None,
              help="Count the track as lost when its position error (after the alignment) exceeds this (m) ...")
@click.option("--lost-steps", type=click.IntRange(1), default=10, show_default=True,
              help="... for this many consecutive matched poses.")
@click.option("-v", "--verbose", "verbose", is_flag=True,
              help="Accepted for evo's -v: replay always prints the statistics and the association.")
@click.option("-p", "p_flag", is_flag=True, help="evo's -p (a window): answered with --plot FILE.")
@click.option("--plot", "--save-plot", "--save_plot", "plot_path", type=click.Path(dir_okay=False), default=None,
              help="Write the figures (png, pdf, svg, eps; missing directories are created): FILE the tracks and "
                   "the APE/RPE over time, FILE_map (tracks coloured by their APE), FILE_xyz, FILE_rpy beside it.")
@click.option("--plot-mode", "--plot_mode", "plot_mode", default="xy", show_default=True,
              type=click.Choice(["xy", "xz", "yz", "yx", "zx", "zy", "xyz"]),
              help="Plane of the tracks in the --plot figures (horizontal, vertical axis; xyz: 3-D), as evo's "
                   "--plot_mode.")
@click.option("-o", "--out", "out", type=click.Path(dir_okay=False), default=None,
              help="Write the leaderboard CSV (the schema of replay eval; missing directories are created).")
@click.option("--trials", "trial_specs", multiple=True, metavar="[NAME=]GLOB",
              help="Trials of one estimator (rpg's --mul_trials, evo_res): files matching GLOB (or REC*.bag:/topic), "
                   "scored one by one and aggregated (mean, median, 95 % t-interval, lost k/N); repeatable, a NAME "
                   "repeated adds trials.")
@click.option("--save_as_tum", "--save-as-tum", "--save_as_kitti", "--save-as-kitti", "--save_as_bag",
              "--save-as-bag", "--save_as_bag2", "save_as", is_flag=True, hidden=True,
              help="evo_traj's conversions: answered with replay convert.")
@click.option("--trials-plot", "trial_plot", type=click.Path(dir_okay=False), default=None,
              help="With --trials: boxplots of each trial set's errors, the APE and RPE and per --lengths length "
                   "(png, pdf, svg, eps).")
@click.option("--save-results", "--save_results", "save_results", default=None, metavar="DIR",
              help="Write a results archive into this directory (per-pose errors, alignment, settings; Parquet + "
                   "JSON), read back by replay res.")
def score_cmd(reference, estimates, align, a_flag, s_flag, n_to_align, align_origin, t_max_diff, t_offset, relations,
              rpe, delta, delta_unit, delta_tol, all_pairs, pairs_from_reference, lengths, lengths_method,
              sync_method, fmt, t_start, t_end, downsample, motion_filter, project_to_plane, kitti_times, columns,
              time_unit, lost_threshold, lost_steps, verbose, p_flag, plot_path, plot_mode, out, trial_specs=(),
              trial_plot=None, save_results=None, save_as=False):
    """Score ESTIMATE trajectories against REFERENCE, as evo_ape/evo_rpe (docs/evo.md).

    Each argument is a trajectory file (TUM, KITTI, EuRoC, CSV) or RECORDING:TOPIC (a .bag, ROS 2 bag
    directory or .mcap and a topic of nav_msgs/Odometry, PoseStamped, PoseWithCovarianceStamped,
    TransformStamped, nav_msgs/Path (last message) or NavSatFix), or RECORDING:tf:PARENT->CHILD.
    """
    from replay.run.score_result import ScoreResult, estimate_name, leaderboard_row
    from replay.run.score_result import settings as score_settings
    from replay.scoring.summary import columns as leaderboard_columns
    from replay.trajectory import io, score
    from replay.trajectory.plot import FORMATS as PLOT_FORMATS
    from replay.trajectory.plot import paths as plot_paths
    from replay.util import outfile
    from replay.util.files import refuse_overlap, write_csv

    if p_flag:
        raise ReplayError("-p: replay never opens a window; write the figures with --plot FILE (png, pdf, svg; evo's "
                          "--save_plot)")
    if save_as:
        raise ReplayError("--save_as_tum/--save_as_kitti/--save_as_bag: replay score writes no trajectories; convert "
                          "one with replay convert SOURCE OUT.tum (.kitti, .csv, .mcap; --format euroc)")
    method = _resolve_align(align, a_flag, s_flag)
    if lengths is not None:
        from replay.trajectory import lengths as by_length

        lengths = by_length.parse(lengths)  # refused before any file is read
    relations = list(dict.fromkeys(relations or ["trans"]))
    want_rpe = rpe or delta is not None or all_pairs
    if "point_distance_error_ratio" in relations and not want_rpe:
        raise ReplayError("-r point_distance_error_ratio is an RPE relation: add --rpe")
    from replay.run import trials as trial_sets

    sets = trial_sets.parse(trial_specs)
    trial_sets.not_reference(sets, reference)
    if not estimates and not sets:
        raise ReplayError("replay score REFERENCE ESTIMATE...: no estimate (give estimates, or --trials GLOB)")
    members = trial_sets.members(sets)
    sources = [*estimates, *(m[3] for m in members)]
    inputs = [io.split(s)[0] for s in (reference, *sources)] + ([Path(kitti_times)] if kitti_times else [])
    if trial_plot and not sets:
        raise ReplayError("--trials-plot: boxplots of trials: give --trials [NAME=]GLOB")
    plots = list(plot_paths(plot_path).values()) if plot_path else []
    for path, what, suffixes in ((out, "--out", None), *((p, "--plot", PLOT_FORMATS) for p in plots),
                                 (trial_plot, "--trials-plot", PLOT_FORMATS)):
        if path:
            refuse_overlap(path, inputs, what)
            outfile.check(path, what, suffixes)
    if save_results:
        from replay.run import archive

        archive.check(save_results, inputs)
    columns, columns_of = io.split_columns(columns, [reference, *sources])
    opts = dict(fmt=fmt, kitti_times=kitti_times, columns=columns, time_unit=time_unit)
    taken = set()
    names = [estimate_name(reference, set())] + [estimate_name(spec, taken) for spec in estimates]
    names += [m[0] for m in members]
    ref, *ests = io.load_all([reference, *sources], names=names, columns_of=columns_of, **opts)
    scores, summary = {}, []
    settings = score_settings(align=method, n_to_align=n_to_align, align_origin=align_origin, t_max_diff=t_max_diff,
                              t_offset=t_offset, relations=relations, delta=(delta or 1.0) if want_rpe else None,
                              delta_unit=delta_unit, delta_tol=delta_tol, all_pairs=all_pairs,
                              pairs_from_reference=pairs_from_reference, lengths=lengths,
                              lengths_method=lengths_method, sync_method=sync_method, t_start=t_start, t_end=t_end,
                              downsample=downsample, motion_filter=motion_filter, project_to_plane=project_to_plane)
    for k, (spec, name, est) in enumerate(zip(sources, names[1:], ests)):
        with trial_sets.naming(members[k - len(estimates)] if k >= len(estimates) else None):
            s = score(ref, est, **settings)
        scores[name] = s
        click.echo(f"{name} vs {ref.name}: {len(s.reference)} of {len(est)} poses matched (reference: {len(ref)} "
                   f"poses; t_max_diff {t_max_diff:g} s{f', t_offset {t_offset:g} s' if t_offset else ''})"
                   + (f"; scale {s.transform[2]:.6f}" if method in ("sim3", "scale") else ""))
        row = leaderboard_row(s, reference=reference, dataset=io.label(reference), estimate=spec, name=name,
                              settings=settings, lost_threshold=lost_threshold, lost_steps=lost_steps)
        summary.append(row)
        if k >= len(estimates):  # a trial: its numbers are in the trials table below
            trial_sets.mark(row, *members[k - len(estimates)][1:])
            continue
        for rel in s.ape:
            click.echo(_block(_title("APE", rel, settings), s.stats("ape", rel)))
        for rel in s.rpe:
            click.echo(_block(_title("RPE", rel, settings), s.stats("rpe", rel)))
        if s.lengths:
            click.echo(by_length.table(s.lengths, lengths_method))
    result = ScoreResult(ref, scores, summary, settings)
    rows = result.output_rows()
    for name in sets:
        click.echo(trial_sets.table(name, [r for r in rows if r["filter"] == f"recorded:{name}" and "trial" in r],
                                    relations, want_rpe))
    plain = [row for row in summary if "trial" not in row]
    if len(plain) > 1:
        rel = relations[0]
        click.echo(f"{'estimate':<24} {'matched':>8} {'APE ' + rel + ' rmse':>22}"
                   + (f" {'RPE ' + rel + ' rmse':>22}" if want_rpe else ""))
        for row in plain:
            click.echo(f"{row['filter'][9:]:<24} {row['matched']:>8} {row.get(f'ape_{rel}_rmse', math.nan):>22.6f}"
                       + (f" {row.get(f'rpe_{rel}_rmse', math.nan):>22.6f}" if want_rpe else ""))
    if out:
        outfile.write(out, "--out", lambda tmp: write_csv(rows, tmp, leaderboard_columns(rows)))
        click.echo(f"leaderboard: {out}")
    if save_results:
        archive.save(result, save_results, reference=reference)
        click.echo(f"results: {save_results} (replay res {save_results})")
    if plot_path:
        from replay.trajectory import plot

        written, removed = plot.write(plot_path, ref, scores, relation=relations[0], mode=plot_mode)
        click.echo(f"plot: {', '.join(map(str, written))}"
                   + (f" (removed the earlier {', '.join(map(str, removed))})" if removed else ""))
    if trial_plot:
        from replay.run import boxplots

        boxplots.write(trial_plot, result)
        click.echo(f"trials plot: {trial_plot}")
