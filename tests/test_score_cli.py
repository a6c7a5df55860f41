"""``replay score``: evo-style statistics, the leaderboard CSV, the plot, and one-line refusals (exit 2)."""
from __future__ import annotations

import csv

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from replay.cli.main import main
from replay.cli.score import score_cmd
from replay.scoring.summary import HEAD, TAIL
from replay.trajectory import load, score
from replay.trajectory.files import write_tum
from replay.trajectory.base import make

if "score" not in main.commands:  # until replay/cli/main.py registers it
    main.add_command(score_cmd)


def run(*args):
    return CliRunner().invoke(main, ["score", *map(str, args)], catch_exceptions=False)


@pytest.fixture
def files(tmp_path):
    rng = np.random.default_rng(0)
    n = 300
    t = 50.0 + np.arange(n) * 0.1
    s = np.arange(n) * 0.1
    p = np.column_stack([8 * np.cos(s / 5), 8 * np.sin(s / 5), 0.1 * s])
    q = Rotation.from_euler("xyz", np.column_stack([0.05 * np.sin(s), np.zeros(n), s / 5])).as_quat()
    write_tum(tmp_path / "gt.tum", make(t, p, q, source="gt"))
    R = Rotation.from_euler("z", 0.5).as_matrix()
    for k, name in enumerate(("vo.tum", "ekf.tum")):
        pe = 1.1 * (p + np.cumsum(rng.normal(0, 0.02, (n, 3)), axis=0)) @ R.T + [k, 2, 0]
        qe = (Rotation.from_matrix(R) * Rotation.from_quat(q) * Rotation.from_rotvec(rng.normal(0, 0.01, (n, 3))))
        write_tum(tmp_path / name, make(t + rng.uniform(-0.003, 0.003, n), pe, qe.as_quat(), source=name))
    return tmp_path


def stat(output: str, title: str, name: str) -> float:
    block = output.split(title, 1)[1]
    line = next(ln for ln in block.splitlines() if ln.strip().startswith(name + "\t"))
    return float(line.split("\t")[1])


def test_score_prints_evo_statistics_and_writes_leaderboard(files):
    out = files / "lb.csv"
    r = run(files / "gt.tum", files / "vo.tum", files / "ekf.tum", "-as", "-r", "trans", "-r", "angle_deg",
            "--rpe", "--delta", 2, "--delta-unit", "m", "-o", out)
    assert r.exit_code == 0, r.output
    lib = score(load(str(files / "gt.tum")), load(str(files / "vo.tum")), align="sim3", relations=["trans"],
                delta=2, delta_unit="m")
    assert "APE w.r.t. translation part (m)\n(with Sim(3) Umeyama alignment)" in r.output
    assert stat(r.output, "APE w.r.t. translation part (m)", "rmse") == pytest.approx(lib.stats()["rmse"], abs=5e-7)
    assert "RPE w.r.t. rotation angle in degrees (deg)\nfor delta = 2 (m) using consecutive pairs" in r.output
    rows = list(csv.DictReader(out.open()))
    assert [row["filter"] for row in rows] == ["recorded:vo", "recorded:ekf"]
    head = list(rows[0])
    assert head[:len(HEAD)] == HEAD and head[-len(TAIL):] == TAIL
    row = rows[0]
    assert row["dataset"] == "gt.tum" and row["runs"] == "1" and row["alignment"] == "sim3"
    assert float(row["ape_trans_rmse"]) == pytest.approx(lib.stats()["rmse"], rel=1e-5)
    assert float(row["ate"]) == pytest.approx(lib.stats()["rmse"], rel=1e-5)
    assert float(row["rpe_trans_rmse"]) == pytest.approx(lib.stats("rpe", "trans")["rmse"], rel=1e-5)
    assert float(row["scale"]) == pytest.approx(1 / 1.1, rel=0.02)


@pytest.mark.slow  # matplotlib: about 3 s
def test_score_plot(files):
    png = files / "plot.png"
    r = run(files / "gt.tum", files / "vo.tum", files / "ekf.tum", "-a", "--rpe", "--plot", png)
    assert r.exit_code == 0, r.output
    assert f"plot: {png}" in r.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_score_evo_flags_map_to_alignments(files):
    for flags, title in ((["-a"], "SE(3) Umeyama"), (["-s"], "scale corrected"), (["--align", "yaw"], "yaw-only"),
                         (["--align-origin"], "with origin alignment"), ([], "not aligned")):
        r = run(files / "gt.tum", files / "vo.tum", *flags)
        assert r.exit_code == 0 and title in r.output, (flags, r.output)


@pytest.mark.parametrize("args,message", [
    (["{d}/gt.tum", "{d}/vo.tum", "--align", "se3", "-s"], "--align se3 and -s (scale) disagree"),
    (["{d}/gt.tum", "{d}/vo.tum", "-a", "--align-origin"], "origin alignment and se3 alignment exclude each other"),
    (["{d}/gt.tum", "{d}/late.tum"], "late.tum against {d}/gt.tum: the time spans do not overlap"),
    (["{d}/gt.tum", "{d}/vo.tum", "-o", "{d}/vo.tum"], "--out {d}/vo.tum: is an input of this command"),
    (["{d}/gt.tum", "{d}/poses.kitti"], "{d}/poses.kitti: KITTI poses carry no stamps"),
    (["{d}/gt.tum", "{d}/dup.tum"], "{d}/dup.tum, row 3: duplicate stamp"),
    (["{d}/gt.tum", "{d}/vo.tum", "-r", "point_distance_error_ratio"], "is an RPE relation: add --rpe"),
    (["{d}/gt.tum", "{d}/missing.bag:/odom"], "{d}/missing.bag: no such file"),
])
def test_score_refuses_in_one_line(files, args, message):
    d = files
    gt = load(str(d / "gt.tum"))
    write_tum(d / "late.tum", make(gt.t + 1000, gt.p, gt.q, source="late"))
    (d / "poses.kitti").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 3)
    (d / "dup.tum").write_text("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n")
    r = CliRunner().invoke(main, ["score", *(a.format(d=d) for a in args)])
    assert r.exit_code == 2, r.output
    err = r.output.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("replay: error: ") and message.format(d=d) in err[0], r.output
    assert "Traceback" not in r.output


@pytest.mark.slow
def test_score_ros_example_bag_orb_slam_se3_as_evo(shared_dir, tmp_path):
    """``evo_ape bag ROS_example.bag groundtruth ORB-SLAM -a``: rmse 5.509938 (evo 1.38)."""
    bag = shared_dir / "datasets" / "bags" / "evo" / "ROS_example.bag"
    r = run(f"{bag}:groundtruth", f"{bag}:ORB-SLAM", f"{bag}:S-PTAM", "-a", "-o", tmp_path / "lb.csv")
    assert r.exit_code == 0, r.output
    assert "ORB-SLAM vs groundtruth: 2550 of 8362 poses matched" in r.output
    assert stat(r.output, "APE w.r.t. translation part (m)", "rmse") == pytest.approx(5.509938, abs=1e-6)
    rows = {row["filter"]: row for row in csv.DictReader((tmp_path / "lb.csv").open())}
    assert set(rows) == {"recorded:ORB-SLAM", "recorded:S-PTAM"}
    assert rows["recorded:ORB-SLAM"]["dataset"] == "ROS_example.bag:groundtruth"
