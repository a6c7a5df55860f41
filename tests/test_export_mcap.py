"""Export of a run: Foxglove MCAP (read back, validated by ../shared/tools/mcap-validate
when node and its node_modules are present) and ROS 2 bag (read back)."""
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from replay.adapters import bags
from replay.cli import main
from replay.outputs.export_mcap import read_estimates


def validator_dir():
    """Where mcap-validate is installed with node_modules ($REPLAY_MCAP_VALIDATE_DIR, else the cache)."""
    from replay.registry import cache_dir

    env = os.environ.get("REPLAY_MCAP_VALIDATE_DIR")
    return Path(env) if env else cache_dir() / "mcap-validate"


def validate(*paths):
    tool = validator_dir()
    if shutil.which("node") is None or not (tool / "node_modules").is_dir():
        pytest.skip(f"MCAP validation skipped: node or {tool}/node_modules missing "
                    "(.ci/run installs it with npm ci)")
    res = subprocess.run(["node", str(tool / "validate_mcap.js"), *map(str, paths)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.count("OK ") == len(paths)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    res = CliRunner().invoke(main, ["eval", "sim/auv-bag", "-f", "ekf,ukf", "--first", "600", "-o",
                                    str(out / "run"), "--mcap", str(out / "run.mcap"),
                                    "--ros2-bag", str(out / "ros2")], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return out


def test_mcap_read_back_same_estimates(run):
    mapping = {"time": "log", "channels": {"ekf": "/replay/ekf/pose", "ukf": "/replay/ukf/pose"},
               "reference": {"position": "/replay/reference/pose"}}
    f = bags.load(run / "run.mcap", mapping=mapping)
    for name in ("ekf", "ukf"):
        est = read_estimates(run / "run" / "estimates" / f"{name}.csv.gz")
        ch = f.channels[name]
        assert ch.valid.sum() == len(est["t"]) == 600
        assert np.array_equal(ch.values[ch.valid], est["x"][:, :3])
        np.testing.assert_allclose(f.t[ch.valid], est["t"] - est["t"][0], atol=1e-9)
    assert f.reference["position"].valid.sum() == 300  # the 10 Hz reference pose in 600 samples at 20 Hz


def test_mcap_channels_and_validator(run):
    rec = bags.read(run / "run.mcap", [])
    assert rec.topics["/replay/ekf/pose"].type == "foxglove.PoseInFrame"
    assert rec.topics["/replay/ekf/path"].count == 1
    assert rec.topics["/replay/ekf/error"].count == 300
    assert rec.topics["/sensors/dvl"].count == 150 and rec.topics["/sensors/depth"].count == 120
    validate(run / "run.mcap", run / "ros2" / "ros2.mcap")


def test_ros2_bag_read_back(run):
    f = bags.load(run / "ros2", mapping={"channels": {"ekf": "/replay/ekf/odom"}})
    est = read_estimates(run / "run" / "estimates" / "ekf.csv.gz")
    assert np.array_equal(f.channels["ekf"].values[f.channels["ekf"].valid], est["x"][:, :3])
    assert {t.type for t in bags.read(run / "ros2", []).topics.values()} == {"nav_msgs/msg/Odometry"}


def test_geodetic_export_location_fix(shared_dir, tmp_path):
    src = shared_dir / "datasets" / "bags" / "derived" / "rl_test1_60s_mcap"
    if not src.is_dir():
        pytest.skip("shared bags missing")
    mapping = Path(__file__).resolve().parents[1] / "docs" / "mappings" / "rl_test1.toml"
    res = CliRunner().invoke(main, ["eval", str(src), "--task", "gps-odom", "--mapping", str(mapping), "-f", "ekf",
                                    "-o", str(tmp_path / "r"), "--first", "400"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["export", str(tmp_path / "r"), "--mcap", str(tmp_path / "g.mcap")])
    assert res.exit_code == 0, res.output
    f = bags.load(tmp_path / "g.mcap", mapping={"channels": {"fix": "/replay/reference/fix"}})
    from replay.tasks.gps_odom import GpsOdomTask

    problem = GpsOdomTask().build(bags.load(src, mapping=mapping).head(400), np.random.default_rng(0))
    want = problem.truth_position[problem.truth_valid]  # the held-out fixes the scorer used
    got = f.channels["fix"].values[f.channels["fix"].valid, :2]  # exported as WGS 84, projected again
    assert len(got) == len(want) > 10
    np.testing.assert_allclose(got - got[0], want - want[0], atol=1e-6)
    validate(tmp_path / "g.mcap")


def test_export_bad_run_dir(tmp_path):
    res = CliRunner().invoke(main, ["export", str(tmp_path), "--mcap", str(tmp_path / "x.mcap")])
    assert res.exit_code == 2 and "manifest.json" in res.output and "Traceback" not in res.output
