"""Real examples at the end of every command's ``--help`` (one place for all of them).

Each runs as written from the repository root with the shared data beside it
(``../shared/datasets``); the simulated datasets need nothing. :func:`add_examples`
sets them as the commands' epilogs after every command is registered.
"""

from __future__ import annotations

import click

BOHAI = "--data-dir ../shared/datasets/bohai"
EXAMPLES: dict[str, list[str]] = {
    "eval": [
        "replay eval sim/auv-sonar --runs 20",
        f"replay eval bohai/20220822_0_6 {BOHAI} --task position --first 1000 --runs 20",
        "replay eval sim/auv-sonar -f ekf,ukf,pf --runs 100 -p pf.n_particles=500 --baseline ekf",
        "replay eval ../shared/datasets/bags/evo/ROS_example.bag --mapping docs/mappings/evo_ros_example.toml "
        "--filters none",
    ],
    "rerun": [
        "replay rerun runs/sim_auv-sonar/sonar/latest/manifest.json",
        "replay rerun runs/sim_auv-sonar/sonar/001/manifest.json -o runs/check -q",
    ],
    "report": ["replay report runs/sim_auv-sonar/sonar/latest", "replay report runs/campaign-example -o report-dir"],
    "reproduce": ["replay reproduce 003 --quick", "replay reproduce 002 --runs 20 --seed 1"],
    "leaderboard": [
        "replay leaderboard runs/campaign-example --sort pos_rmse",
        "replay leaderboard runs/campaign-example runs/sim_auv-sonar/sonar/latest -o merged.csv",
    ],
    "export": [
        "replay export runs/sim_auv-sonar/sonar/latest --mcap run.mcap",
        "replay export runs/campaign-example --dataset sim/auv-sonar --run 3 --mcap auv-run3.mcap",
        "replay export runs/campaign-example --dataset bohai/20220822_0_6 --filter ekf,ukf --mcap bohai.mcap "
        f"--ros2-bag bohai_bag {BOHAI} -q",
    ],
    "inspect": [
        "replay inspect ../shared/datasets/bags/robot_localization/test1.bag",
        "replay inspect ../shared/datasets/bags/evo/ROS_example.bag",
    ],
    "list": [
        "replay list filters",
        "replay list filters pf",
        "replay list tasks position",
        "replay list datasets sim/ungm",
    ],
    "score": [
        "replay score gt.tum est.tum -a",
        "replay score gt.tum est.tum --rpe --delta 1 --delta-unit m --plot rpe.png",
        "replay score gt.tum --trials 'orb=runs/orb_*.txt' -a --lengths 10%,20%,30% --save-results res/orb",
        "replay score ../shared/datasets/bags/evo/ROS_example.bag:groundtruth "
        "../shared/datasets/bags/evo/ROS_example.bag:ORB-SLAM -a",
    ],
    "res": [
        "replay res results/orb results/vins --format latex -o table.tex",
        "replay res results/orb --table trials --plot boxes.png",
    ],
    "convert": [
        "replay convert ../shared/datasets/bags/evo/ROS_example.bag:groundtruth gt.tum",
        "replay convert est.txt est.mcap --topic /slam/pose --frame-id map",
    ],
    "campaign run": [
        "replay campaign run campaigns/example.toml --out runs/campaign-example",
        "replay campaign run campaigns/example.toml --workers 2 -q",
        "replay campaign run campaigns/example.toml --dask-local 2",
    ],
    "tune": [
        "replay tune sim/linear --filters kf --split seeds -p 'kf.q_scale=log[0.01,10]' "
        "-p 'kf.r_scale=log[0.1,20]' --objective nll --trials 40 --runs 5 --out runs/tune-linear",
        f"replay tune bohai/20220822_0_6 {BOHAI} --task position --rate 1 --filters ekf,ukf,pf "
        "--space campaigns/tune_space.toml --train-segment 0.6 --trials 50 --out runs/tune-0_6",
        f"replay tune --train bohai/20220822_0_3,bohai/20220822_0_4 --test bohai/20220822_0_5,bohai/20220822_0_6 "
        f"{BOHAI} --task position --rate 1 --space campaigns/tune_space.toml --out runs/tune-seq",
    ],
    "datasets list": [f"replay datasets list {BOHAI}", "replay datasets list"],
    "datasets info": [f"replay datasets info bohai/20220822_0_6 {BOHAI}", "replay datasets info sim/auv-sonar"],
    "datasets fetch": ["replay datasets fetch bohai/20220822_0_6", "replay datasets fetch bohai/20220822_0_6 --force"],
    "datasets make": [
        "replay datasets make sim/lake-depth --out lake.csv",
        "replay datasets make sim/auv-bag --out auv_bag",
    ],
}


def epilog(lines: list[str]) -> str:
    """Click epilog text kept verbatim (``\\b``) under an "Examples" heading."""
    return "\b\nExamples:\n" + "\n".join(f"  {line}" for line in lines)


def add_examples(group: click.Group, prefix: str = "") -> None:
    """Set the examples of every command of ``group`` (recursively) as its epilog."""
    for name, cmd in group.commands.items():
        key = f"{prefix}{name}"
        if isinstance(cmd, click.Group):
            add_examples(cmd, key + " ")
        if key in EXAMPLES:
            cmd.epilog = epilog(EXAMPLES[key])
