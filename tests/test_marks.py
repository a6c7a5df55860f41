"""Rows that are not a filter's error are marked, never ranked (issue 40 item 2): a filter whose
estimate never moves, and a row whose reference is one of its inputs (a topic scored against itself)."""
import csv

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli import main

HEAD = 'time = "header"\n\n[channels]\nimu = { topic = "/imu/data", type = "sensor_msgs/msg/Imu", fuse = ["gyro"] }\n'
REF = '\n[reference]\nposition = { topic = "/reference/pose", type = "geometry_msgs/msg/PoseStamped" }\n'
POSE = 'pose = { topic = "/reference/pose", type = "geometry_msgs/msg/PoseStamped", fuse = ["position"] }\n'
DVL = 'dvl = { topic = "/dvl/twist", type = "geometry_msgs/msg/TwistWithCovarianceStamped", fuse = ["velocity"] }\n'
EST = '\n[estimates]\ntruth = { topic = "/reference/pose", type = "geometry_msgs/msg/PoseStamped" }\n'


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    from replay.sim.auv_bag import make_bag

    d = tmp_path_factory.mktemp("bag")
    make_bag(d / "auv", np.random.default_rng(0), duration=40.0)
    (d / "still.toml").write_text(HEAD + REF)  # the gyro only: no position, no velocity
    (d / "refin.toml").write_text(HEAD + DVL + POSE + REF + EST)  # the reference's topic fused and recorded
    return d


def _eval(bag, mapping, out, filters="ekf,ukf"):
    res = CliRunner().invoke(main, ["eval", str(bag / "auv"), "--mapping", str(bag / mapping), "--task", "fusion",
                                    "-f", filters, "--runs", "2", "-q", "-o", str(out)])
    assert res.exit_code == 0, res.output
    with open(out / "leaderboard.csv", newline="") as fh:
        return res.output, {r["filter"]: r for r in csv.DictReader(fh)}


def test_a_fusion_whose_estimate_could_never_move_is_refused_before_any_ranking(bag, tmp_path):
    # the gyro alone constrains no speed: the fusion task refuses it (issue 34 item 5) before the
    # 'still' mark of replay/scoring/marks.py would be needed; nothing is written
    res = CliRunner().invoke(main, ["eval", str(bag / "auv"), "--mapping", str(bag / "still.toml"), "--task",
                                    "fusion", "-f", "ekf,ukf", "--runs", "2", "-q", "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and "no input constrains the speed (inputs: imu.gyro)" in res.output
    assert "Traceback" not in res.output and not (tmp_path / "o" / "leaderboard.csv").exists()


def test_a_reference_that_is_also_an_input_is_marked_on_every_row_that_reads_it(bag, tmp_path):
    text, rows = _eval(bag, "refin.toml", tmp_path / "o", "ekf")
    assert rows["ekf"]["reference_input"] == "pose.position read from /reference/pose, the reference's topic"
    assert rows["recorded:truth"]["reference_input"] == "recorded from /reference/pose, the reference's topic"
    assert float(rows["recorded:truth"]["pos_rmse"]) == 0.0 and float(rows["ekf"]["pos_rmse"]) < 0.05
    assert "still" not in rows["ekf"] or rows["ekf"]["still"] == ""  # it moves
    for name in ("ekf", "measurements", "recorded:truth"):
        assert f"\n{name} (ref=input) " in text
        assert f"{name}: not ranked: reference is an input (" in text


def test_an_independent_reference_and_a_moving_filter_are_not_marked(bag, tmp_path):
    (bag / "plain.toml").write_text(HEAD + DVL + REF)
    text, rows = _eval(bag, "plain.toml", tmp_path / "o", "ekf")
    assert rows["ekf"].get("still", "") == "" and rows["ekf"].get("reference_input", "") == ""
    assert "not ranked" not in text and "(still)" not in text and "(ref=input)" not in text


def test_still():
    from replay.scoring.scorer import still

    start = np.array([[1000.0, -2000.0]] * 5)
    assert still(start) and still(np.vstack([start, [[np.nan, np.nan]]]))
    assert not still(start + np.array([[0, 0], [0, 0], [0, 1e-3], [0, 0], [0, 0]]))  # a millimetre is a move
    assert still(start + 1e-7 * np.arange(5)[:, None] / 5)  # below 1e-9 of 2000 m: rounding
    assert not still(start[:1]) and not still(np.empty((0, 2)))
