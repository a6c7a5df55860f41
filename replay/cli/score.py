"""``replay score REFERENCE ESTIMATE...``: score recorded trajectories as evo_ape / evo_rpe do.

Registered in :mod:`replay.cli.main` (``main.add_command(score_cmd)``). The numbers come from
:mod:`replay.trajectory`; the CSV has the leaderboard schema of :mod:`replay.scoring.summary`.
"""

from __future__ import annotations

import click


@click.command("score")
@click.argument("reference")
@click.argument("estimates", nargs=-1)
@click.option(
    "--align",
    type=click.Choice(["none", "yaw", "se3", "sim3", "scale"]),
    default=None,
    help="Alignment of each estimate onto the reference: none (default, as evo), yaw (4-DoF), se3, "
    "sim3, scale (scale only).",
)
@click.option("-a", "a_flag", is_flag=True, help="evo's -a: SE(3) alignment (-as: Sim(3)).")
@click.option(
    "-s",
    "--correct-scale",
    "--correct_scale",
    "s_flag",
    is_flag=True,
    help="evo's -s: correct the scale (alone: scale only; with -a: Sim(3)).",
)
@click.option(
    "--n-to-align",
    "--n_to_align",
    "n_to_align",
    type=click.IntRange(1),
    default=None,
    help="Fit the alignment on the first N matched poses only (default: all).",
)
@click.option(
    "--align-origin",
    "--align_origin",
    "align_origin",
    is_flag=True,
    help="Move each estimate so that its first pose is the reference's first pose.",
)
@click.option(
    "--t-max-diff",
    "--t_max_diff",
    "t_max_diff",
    type=click.FloatRange(0),
    default=0.01,
    show_default=True,
    help="Largest stamp difference (s) of an associated pose pair.",
)
@click.option(
    "--t-offset",
    "--t_offset",
    "t_offset",
    type=float,
    default=0.0,
    show_default=True,
    help="Constant offset (s) added to the estimates' stamps before association.",
)
@click.option(
    "-r",
    "--pose-relation",
    "--pose_relation",
    "relations",
    multiple=True,
    type=click.Choice(
        [
            "trans",
            "rot",
            "full",
            "angle_deg",
            "angle_rad",
            "point_distance",
            "point_distance_error_ratio",
            "trans_part",
            "rot_part",
        ]
    ),
    help="Pose relation (repeatable; default trans): evo's -r.",
)
@click.option("--rpe", is_flag=True, help="Also compute the RPE (implied by --delta).")
@click.option(
    "-d",
    "--delta",
    type=click.FloatRange(0, min_open=True),
    default=None,
    help="RPE pose distance (default 1) in --delta-unit.",
)
@click.option(
    "-u",
    "--delta-unit",
    "--delta_unit",
    "delta_unit",
    type=click.Choice(["f", "m", "d", "r", "s"]),
    default="f",
    show_default=True,
    help="f frames, m metres, d degrees, r radians, s seconds.",
)
@click.option(
    "-t",
    "--delta-tol",
    "--delta_tol",
    "delta_tol",
    type=click.FloatRange(0),
    default=0.1,
    show_default=True,
    help="Relative delta tolerance of --all-pairs (m, d, r, s).",
)
@click.option(
    "--all-pairs",
    "--all_pairs",
    "all_pairs",
    is_flag=True,
    help="RPE over all pairs at the delta instead of consecutive ones.",
)
@click.option(
    "--pairs-from-reference",
    "--pairs_from_reference",
    "pairs_from_reference",
    is_flag=True,
    help="Choose the RPE pairs on the reference instead of the estimate.",
)
@click.option(
    "--lengths",
    "lengths",
    default=None,
    help="Relative errors over sub-trajectory lengths, rpg_trajectory_evaluation / KITTI style: "
    "10%,20%,30%,40%,50% of the reference's path length, or metres (100,200,...,800).",
)
@click.option(
    "--lengths-method",
    "--lengths_method",
    "lengths_method",
    type=click.Choice(["rpg", "kitti"]),
    default="rpg",
    show_default=True,
    help="Sub-trajectories of --lengths: rpg (every start, end nearest to the length) or kitti "
    "(every 10th start, first end beyond the length).",
)
@click.option(
    "--sync-method",
    "--sync_method",
    "sync_method",
    type=click.Choice(["nearest", "interpolation"]),
    default="nearest",
    show_default=True,
    help="Association: the nearest stamp (evo's nearest_time), or interpolation: the denser trajectory "
    "resampled at the other's matched stamps (evo's --sync_method interpolation).",
)
@click.option(
    "--t-start",
    "--t_start",
    "t_start",
    type=float,
    default=None,
    help="Score only poses stamped at or after this (s; the estimate's stamps with --t-offset).",
)
@click.option("--t-end", "--t_end", "t_end", type=float, default=None, help="... and at or before this (s).")
@click.option(
    "--downsample",
    type=click.IntRange(2),
    default=None,
    help="Keep N matched pose pairs, evenly spaced (evo's --downsample).",
)
@click.option(
    "--motion-filter",
    "--motion_filter",
    "motion_filter",
    type=(float, float),
    default=None,
    help="DIST ANGLE: keep a pair when the reference moved DIST m or turned ANGLE deg since the last kept "
    "one (evo's --motion_filter).",
)
@click.option(
    "--project-to-plane",
    "--project_to_plane",
    "project_to_plane",
    type=click.Choice(["xy", "xz", "yz"]),
    default=None,
    help="Project both trajectories onto this plane after the alignment (evo's --project_to_plane).",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["tum", "kitti", "euroc", "csv"]),
    default=None,
    help="Format of the trajectory files (default: from the header's column names, else the "
    "extension and the column count; a CSV whose order they cannot tell is refused).",
)
@click.option(
    "--kitti-times",
    type=click.Path(dir_okay=False),
    default=None,
    help="Stamps of KITTI poses, one per line (default: times.txt beside them).",
)
@click.option(
    "--columns",
    multiple=True,
    help="Columns of a plain CSV, e.g. t=time,x=px,y=py,z=pz,qx=qx,qy=qy,qz=qz,qw=qw (or roll/pitch/yaw); "
    "FILE=t=time,... for one file only (repeatable), e.g. a CSV estimate against a TUM reference.",
)
@click.option(
    "--time-unit",
    type=click.Choice(["s", "ms", "us", "ns"]),
    default=None,
    help="Unit of the CSV time column (default: the unit its header names, else the one in which "
    "the stamps are Unix time, else s).",
)
@click.option(
    "--lost-threshold",
    type=click.FloatRange(0, min_open=True),
    default=None,
    help="Count the track as lost when its position error (after the alignment) exceeds this (m) ...",
)
@click.option(
    "--lost-steps",
    type=click.IntRange(1),
    default=10,
    show_default=True,
    help="... for this many consecutive matched poses.",
)
@click.option(
    "-v",
    "--verbose",
    "verbose",
    is_flag=True,
    help="Accepted for evo's -v: replay always prints the statistics and the association.",
)
@click.option("-p", "p_flag", is_flag=True, help="evo's -p (a window): answered with --plot FILE.")
@click.option(
    "--plot",
    "--save-plot",
    "--save_plot",
    "plot_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="Write the figures (png, pdf, svg, eps; missing directories are created): FILE the tracks and "
    "the APE/RPE over time, FILE_map (tracks coloured by their APE), FILE_xyz, FILE_rpy beside it.",
)
@click.option(
    "--plot-mode",
    "--plot_mode",
    "plot_mode",
    default="xy",
    show_default=True,
    type=click.Choice(["xy", "xz", "yz", "yx", "zx", "zy", "xyz"]),
    help="Plane of the tracks in the --plot figures (horizontal, vertical axis; xyz: 3-D), as evo's --plot_mode.",
)
@click.option(
    "-o",
    "--out",
    "out",
    type=click.Path(dir_okay=False),
    default=None,
    help="Write the leaderboard CSV (the schema of replay eval; missing directories are created).",
)
@click.option(
    "--trials",
    "trial_specs",
    multiple=True,
    metavar="[NAME=]GLOB",
    help="Trials of one estimator (rpg's --mul_trials, evo_res): files matching GLOB (or REC*.bag:/topic), "
    "scored one by one and aggregated (mean, median, 95 % t-interval, lost k/N); repeatable, a NAME "
    "repeated adds trials.",
)
@click.option(
    "--save_as_tum",
    "--save-as-tum",
    "--save_as_kitti",
    "--save-as-kitti",
    "--save_as_bag",
    "--save-as-bag",
    "--save_as_bag2",
    "save_as",
    is_flag=True,
    hidden=True,
    help="evo_traj's conversions: answered with replay convert.",
)
@click.option(
    "--trials-plot",
    "trial_plot",
    type=click.Path(dir_okay=False),
    default=None,
    help="With --trials: boxplots of each trial set's errors, the APE and RPE and per --lengths length "
    "(png, pdf, svg, eps).",
)
@click.option(
    "--save-results",
    "--save_results",
    "save_results",
    default=None,
    metavar="DIR",
    help="Write a results archive into this directory (per-pose errors, alignment, settings; Parquet + "
    "JSON), read back by replay res.",
)
def score_cmd(**options):
    """Score ESTIMATE trajectories against REFERENCE, as evo_ape/evo_rpe (docs/evo.md).

    Each argument is a trajectory file (TUM, KITTI, EuRoC, CSV) or RECORDING:TOPIC (a .bag, ROS 2 bag
    directory or .mcap and a topic of nav_msgs/Odometry, PoseStamped, PoseWithCovarianceStamped,
    TransformStamped, nav_msgs/Path (last message) or NavSatFix), or RECORDING:tf:PARENT->CHILD.
    """
    from replay.cli import score_steps as steps

    o = steps.checked(options)  # every refusal before a file is read
    ref, estimates = steps.load(o)
    result = steps.score_all(o, ref, estimates)
    steps.write(o, result)
