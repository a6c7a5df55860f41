"""ROS bags and MCAP: the real recordings of ../shared/datasets/bags, mappings,
the gps-odom task on three forms of the same data, round trips, bad input."""
import csv
import os
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from replay.adapters import bags, rosmsg
from replay.cli import main
from replay.util.errors import DataError, ReplayError

REPO = Path(__file__).resolve().parents[1]
RL_MAP = REPO / "docs" / "mappings" / "rl_test1.toml"
RL60_MAP = REPO / "docs" / "mappings" / "rl_test1_60s.toml"

# (path, {topic: count}, span s) from ../shared/datasets/bags/README.md
RECORDINGS = [
    ("robot_localization/test1.bag", {"/imu/data": 11865, "/husky_velocity_controller/odom": 3952, "/fix": 989}, 395),
    ("robot_localization/test3_groovy.bag", {"/ardrone/imu": 25217, "/ardrone/odometry/raw": 25217}, 138),
    ("derived/rl_test1_60s_sqlite3", {"/imu/data": 1801, "/husky_velocity_controller/odom": 600, "/fix": 150}, 60),
    ("derived/rl_test1_60s_mcap", {"/imu/data": 1801, "/husky_velocity_controller/odom": 600, "/fix": 150}, 60),
    ("evo/ROS_example.bag", {"groundtruth": 12765, "ORB-SLAM": 8362, "S-PTAM": 5439}, 889),
    ("evo/nav2_turtlebot.mcap", {"/odom": 2639, "/amcl_pose": 135, "/tf": 5422, "/tf_static": 1}, 97),
]


@pytest.fixture(scope="module")
def bagdir(shared_dir):
    path = shared_dir / "datasets" / "bags"
    if not path.is_dir():
        if os.environ.get("REPLAY_REQUIRE_SHARED") == "1":
            pytest.fail(f"{path} missing")
        pytest.skip(f"{path} missing")
    return path


def run_cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


# ---------------------------------------------------------------- real recordings

@pytest.mark.parametrize("rel,counts,span", RECORDINGS, ids=[r[0] for r in RECORDINGS])
def test_recording_counts_and_span(bagdir, rel, counts, span):
    rec = bags.read(bagdir / rel, [])
    assert {k: v.count for k, v in rec.topics.items()} == counts
    assert rec.truncated is None
    assert abs((rec.end_ns - rec.start_ns) / 1e9 - span) < 1.0


@pytest.mark.slow
def test_inspect_proposes_sensible_mappings(bagdir):
    def entries(rel):
        mp = bags.inspect(bagdir / rel)["mapping"]
        return {(e.name, e.topic, e.reference) for e in mp.entries}

    assert entries("robot_localization/test1.bag") == {
        ("imu", "/imu/data", False), ("odom", "/husky_velocity_controller/odom", False),
        ("gps", "/fix", False), ("position", "/fix", True)}
    assert entries("evo/ROS_example.bag") == {
        ("pose", "ORB-SLAM", False), ("pose2", "S-PTAM", False), ("position", "groundtruth", True)}
    assert entries("evo/nav2_turtlebot.mcap") == {("odom", "/odom", False), ("pose", "/amcl_pose", False)}
    res = run_cli("inspect", bagdir / "robot_localization/test1.bag")
    assert res.exit_code == 0
    assert "11865" in res.output and "2.50" in res.output and '[reference.position]\ntopic = "/fix"' in res.output


def test_frame_axis_union_and_both_times(bagdir):
    f = bags.load(bagdir / "derived/rl_test1_60s_mcap", mapping=RL_MAP)
    assert len(f) == 1801 + 600 + 150  # no stamp shared by two topics here
    assert f.channels["imu"].valid.sum() == 1801 and f.channels["gps"].valid.sum() == 150
    assert not (f.channels["imu"].valid & f.channels["gps"].valid).any()  # never invented
    assert f.meta["t0_ns"] == 1432235497988949113  # first imu header.stamp
    assert f.meta["crs"] == "EPSG:32619" and f.epoch == pytest.approx(1432235497.988949113)
    log = f.channels["imu_log_time"]
    lag = log.values[log.valid] - f.t[log.valid]
    assert 0 < np.median(lag) < 0.1  # log (receive) time after header stamp
    g = bags.load(bagdir / "derived/rl_test1_60s_mcap", mapping=RL_MAP, time="log")
    assert g.meta["t0_ns"] == 1432235498025043042
    assert np.allclose(g.channels["imu_header_time"].values[g.channels["imu"].valid] + 0.0, 
                       f.t[f.channels["imu"].valid] - (g.meta["t0_ns"] - f.meta["t0_ns"]) / 1e9)


def test_sim_time_recording(bagdir):
    f = bags.load(bagdir / "evo/nav2_turtlebot.mcap")
    assert f.meta["sim_time"] and f.epoch is None
    assert 900e9 < f.meta["t0_ns"] < 1000e9
    assert f.report.find("info", "t")


@pytest.mark.slow
def test_gps_odom_same_leaderboard_three_forms(bagdir, tmp_path):
    boards = []
    for i, rel in enumerate(["robot_localization/test1.bag", "derived/rl_test1_60s_sqlite3",
                             "derived/rl_test1_60s_mcap"]):
        res = run_cli("eval", bagdir / rel, "--task", "gps-odom", "--mapping", RL60_MAP,
                      "-f", "ekf,pf", "-o", tmp_path / str(i))
        assert res.exit_code == 0, res.output
        with open(tmp_path / str(i) / "leaderboard.csv") as fh:
            boards.append({r["filter"]: r for r in csv.DictReader(fh)})
    for other in boards[1:]:
        for name, row in boards[0].items():
            for k in ("pos_rmse", "x_rmse", "y_rmse", "scored", "masked"):
                assert float(other[name][k]) == pytest.approx(float(row[k]), abs=1e-9)
    assert 0.5 < float(boards[0]["ekf"]["pos_rmse"]) < 5.0  # about the fix noise (1 m sigma)
    assert int(boards[0]["ekf"]["scored"]) == 150 - 30  # every 5th fix fed, the rest scored


# ---------------------------------------------------------------- round trips

def _assert_same_frame(f1, f2, atol):
    assert np.array_equal(f1.t, f2.t)
    for g1, g2 in ((f1.channels, f2.channels), (f1.reference, f2.reference)):
        assert g1.keys() == g2.keys()
        for k in g1:
            assert np.array_equal(g1[k].valid, g2[k].valid), k
            v = g1[k].valid
            np.testing.assert_allclose(g2[k].values[v], g1[k].values[v], rtol=0, atol=atol, err_msg=k)


def test_round_trip_frame_ros2_frame(bagdir, tmp_path):
    from replay.outputs.export_ros2 import write_frame_bag

    f1 = bags.load(bagdir / "derived/rl_test1_60s_sqlite3", mapping=RL_MAP)
    assert write_frame_bag(f1, tmp_path / "rt") == 2551
    f2 = bags.load(tmp_path / "rt", mapping=RL_MAP)
    _assert_same_frame(f1, f2, atol=1e-8)  # NavSatFix: through the inverse UTM projection
    for k in ("imu", "imu_accel", "odom", "odom_velocity", "odom_rate", "gps_status"):
        assert np.array_equal(f1.channels[k].values[f1.channels[k].valid],
                              f2.channels[k].values[f2.channels[k].valid]), k  # bit-exact


def test_auv_bag_round_trip_and_pressure(tmp_path):
    from replay.outputs.export_ros2 import write_frame_bag
    from replay.sim.auv_bag import AUV_MAPPING, make_bag

    make_bag(tmp_path / "auv", np.random.default_rng(3), duration=30.0, sigma_p=0.0)
    f1 = bags.load(tmp_path / "auv", mapping=AUV_MAPPING)
    assert f1.channels["dvl"].valid.sum() == 150 and f1.channels["depth"].valid.sum() == 120
    # sigma_p = 0: depth from pressure equals the true depth (= -up of the reference pose)
    both = f1.channels["depth"].valid
    ref = bags.load(tmp_path / "auv", mapping={"reference": {"position": "/reference/pose"}}, time="header")
    d = f1.channels["depth"].values[both]
    assert np.all((d > 7.9) & (d < 12.1))
    write_frame_bag(f1, tmp_path / "auv2")
    _assert_same_frame(f1, bags.load(tmp_path / "auv2", mapping=AUV_MAPPING), atol=1e-12)
    assert ref.reference["position"].valid.sum() == 300


def test_pressure_to_depth_known_value():
    from types import SimpleNamespace

    class M:  # one FluidPressure message
        header = SimpleNamespace(frame_id="p")
        fluid_pressure = 101325.0 + 1025.0 * 9.80665 * 12.5
    out = rosmsg.convert("pressure", [M()])
    assert out["depth"][0][0] == pytest.approx(12.5, abs=1e-12)
    out = rosmsg.convert("pressure", [M()], options={"water_density": 1000.0})
    assert out["depth"][0][0] == pytest.approx(12.5 * 1.025, abs=1e-12)


def test_quaternion_round_trip():
    rpy = np.array([[0.1, -0.2, 3.0], [0.0, 0.0, -1.5]])
    np.testing.assert_allclose(rosmsg.quat_to_rpy(rosmsg.rpy_to_quat(rpy)), rpy, atol=1e-12)


# ---------------------------------------------------------------- bad input

def _write_bag(path, stamps_ns, status=0):
    """A tiny ROS 2 bag with NavSatFix on /fix at the given header stamps."""
    from replay.outputs.export_ros2 import BagOut

    out = BagOut(path)
    T = out.T
    c = out.connection("/fix", "sensor_msgs/msg/NavSatFix")
    out.connection("/empty", "sensor_msgs/msg/Imu")
    for i, s in enumerate(stamps_ns):
        st = status if i == 1 else 0
        out.write(c, 10**18 + i * 10**8, T["sensor_msgs/msg/NavSatFix"](
            header=out.header(s, "gps"), status=T["sensor_msgs/msg/NavSatStatus"](status=st, service=1),
            latitude=42.0 + i * 1e-5, longitude=-71.0, altitude=5.0, position_covariance=np.zeros(9),
            position_covariance_type=0))
    out.close()
    return path


def _one_line_error(args, *words):
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 2, res.output
    err = res.output.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


def test_fix_status_masked(tmp_path):
    p = _write_bag(tmp_path / "b", [10**18 + k * 10**8 for k in range(4)], status=-1)
    f = bags.load(p, mapping={"channels": {"gps": "/fix"}})
    assert f.channels["gps"].valid.tolist() == [True, False, True, True]
    assert f.report.find("masked", "gps")[0].count == 1
    np.testing.assert_allclose(f.channels["gps"].values[0], 0.0, atol=1e-9)  # origin = first fix


def test_mapping_errors_name_file_and_topic(tmp_path):
    p = _write_bag(tmp_path / "b", [10**18 + k * 10**8 for k in range(3)])
    m = tmp_path / "m.toml"
    m.write_text('[channels]\ngps = { topic = "/fix", type = "sensor_msgs/msg/Bogus" }\n')
    _one_line_error(["eval", p, "--mapping", m], "m.toml", "unknown message type", "Bogus")
    m.write_text('[channels]\ngps = "/fixx"\n')
    _one_line_error(["eval", p, "--mapping", m], str(p), "/fixx", "did you mean /fix")
    m.write_text('[channels]\nimu = "/empty"\n')
    _one_line_error(["eval", p, "--mapping", m], str(p), "/empty", "no messages")
    q = _write_bag(tmp_path / "c", [10**18, 10**18 + 10**8, 10**18 + 10**8])
    m.write_text('[channels]\ngps = "/fix"\n')
    _one_line_error(["eval", q, "--mapping", m], str(q), "/fix", "non-increasing header stamps at message 2")


def _cut(src: Path, dst: Path, frac: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * frac)])
    return dst


@pytest.mark.parametrize("frac", [0.02, 0.5, 0.95])
def test_truncated_files(bagdir, tmp_path, frac, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a refused eval's numbered directory would be made here (issue 40: not the checkout)
    bag = _cut(bagdir / "robot_localization/test1.bag", tmp_path / "t.bag", frac)
    _one_line_error(["eval", bag, "--task", "gps-odom"], str(bag), "truncated")
    mc = _cut(bagdir / "derived/rl_test1_60s_mcap/rl_test1_60s_mcap.mcap", tmp_path / "t.mcap", frac)
    err = _one_line_error(["eval", mc, "--task", "gps-odom", "--mapping", RL_MAP], str(mc), "truncated")
    d = tmp_path / "sq"
    shutil.copytree(bagdir / "derived/rl_test1_60s_sqlite3", d)
    db = d / "rl_test1_60s_sqlite3.db3"
    db.chmod(0o644)
    _cut(bagdir / "derived/rl_test1_60s_sqlite3/rl_test1_60s_sqlite3.db3", db, frac)
    _one_line_error(["eval", d, "--task", "gps-odom", "--mapping", RL_MAP], str(d))
    assert not (tmp_path / "runs").exists()  # the refused runs left no directory


def test_truncated_mcap_prefix_flagged_when_allowed(bagdir, tmp_path):
    # 0.95: the first of the file's two chunks (about 1 MB of 1.17 MB) is whole
    mc = _cut(bagdir / "derived/rl_test1_60s_mcap/rl_test1_60s_mcap.mcap", tmp_path / "t.mcap", 0.95)
    with pytest.raises(DataError, match="truncated"):
        bags.load(mc, mapping=RL_MAP)
    f = bags.load(mc, mapping=RL_MAP, allow_truncated=True)
    assert f.meta["truncated"] and f.report.find("flagged")
    assert "TRUNCATED" in f.report.find("flagged")[0].reason
    assert 0 < f.channels["gps"].valid.sum() < 150
