"""Export of a run: Foxglove MCAP (read back, validated by ../shared/tools/mcap-validate
when node and its node_modules are present) and ROS 2 bag (read back); the streamed
MCAP writer gives the same messages and chunk layout as the whole-file writer it
replaced (a digest recorded from that writer), and keeps those channels' messages
unchanged now that frame transforms and covariance ellipsoids are added; positions of
north-east-down tasks are exported in east-north-up. The new channels themselves:
tests/test_export_foxglove.py."""
import os
import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from replay.adapters import bags
from replay.cli import main
from replay.outputs.export_mcap import read_estimates


def validator_dir():
    """Where mcap-validate is installed with node_modules ($REPLAY_MCAP_VALIDATE_DIR, else the cache)."""
    from replay.data.registry import cache_dir

    env = os.environ.get("REPLAY_MCAP_VALIDATE_DIR")
    return Path(env) if env else cache_dir() / "mcap-validate"


VALIDATOR_TIMEOUT = 20  # s per call: about 0.3 s a file quiet, 1.5 s with a dozen at once on 2 loaded cores


def _node(cmd, report_dir):
    """Run the validator in its own process group: (exit status, stdout, stderr), the status None
    when it did not end within VALIDATOR_TIMEOUT s. Then node is asked for its diagnostic report
    (JavaScript stack, pending libuv handles: where it waits), which is added to stderr, and the
    whole group is killed: a hang costs VALIDATOR_TIMEOUT s, not more."""
    proc = subprocess.Popen(["node", "--report-on-signal", "--report-signal=SIGUSR2",
                             f"--report-directory={report_dir}", *cmd], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=VALIDATOR_TIMEOUT)
        return proc.returncode, out, err
    except subprocess.TimeoutExpired:
        import json
        import signal
        import time

        proc.send_signal(signal.SIGUSR2)
        time.sleep(2)  # node writes its report from its own thread
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        for rep in Path(report_dir).glob("report.*.json"):
            data = json.loads(rep.read_text())
            err += "\nnode report: stack " + json.dumps(data.get("javascriptStack", {}).get("stack"))
            err += "\nlibuv handles " + json.dumps([h.get("type") for h in data.get("libuv", []) if h.get("is_active")])
        return None, out, err


def validate(*paths):
    tool = validator_dir()
    if shutil.which("node") is None or not (tool / "node_modules").is_dir():
        pytest.skip(f"MCAP validation skipped: node or {tool}/node_modules missing "
                    "(.ci/run installs it with npm ci)")
    import tempfile

    cmd = [str(tool / "validate_mcap.js"), *map(str, paths)]
    with tempfile.TemporaryDirectory(prefix="mcap-validate-") as reports:
        code, out, err = _node(cmd, reports)
        if code is None:  # seen in loaded full-suite runs only, never alone: once more, saying where it waited
            warnings.warn(f"MCAP validator did not end within {VALIDATOR_TIMEOUT} s on {[str(p) for p in paths]}; "
                          f"retried. Its output: {out!r}; {err!r}")
            code, out, err = _node(cmd, reports)
    assert code is not None, f"MCAP validator did not end within {VALIDATOR_TIMEOUT} s twice: {out}{err}"
    assert code == 0, out + err
    assert out.count("OK ") == len(paths)


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


def rosbags_odometry(bag) -> dict:
    """{topic: (n, 3) positions} of a bag's nav_msgs/Odometry messages, read and deserialised by rosbags."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    ts, got = get_typestore(Stores.ROS2_HUMBLE), {}
    with Reader(bag) as reader:
        for conn, _, raw in reader.messages():
            p = ts.deserialize_cdr(raw, conn.msgtype).pose.pose.position
            got.setdefault(conn.topic, []).append((p.x, p.y, p.z))
    return {k: np.array(v) for k, v in got.items()}


def uncompressed_size(run_dir, tmp_path) -> int:
    """The size of the same odometry bag with uncompressed chunks, as the export wrote it before issue 16."""
    from replay.adapters.bags.writer import BagOut
    from replay.outputs.export_ros2 import _write_run
    from replay.outputs.run_data import load_run

    _write_run(BagOut(tmp_path / "plain", compression=None), load_run(run_dir))
    return sum(p.stat().st_size for p in (tmp_path / "plain").iterdir())


def check_compressed_bag(bag, run_dir, tmp_path, ratio=3) -> tuple[int, int]:
    """zstd chunks and rosbag2 metadata as `ros2 bag record -s mcap` writes them, the positions read
    back by rosbags, and at most 1/``ratio`` of the uncompressed size; returns (size, uncompressed)."""
    from mcap.reader import make_reader
    from ruamel.yaml import YAML

    with open(bag / f"{bag.name}.mcap", "rb") as fh:
        s = make_reader(fh).get_summary()
    assert s.chunk_indexes and {c.compression for c in s.chunk_indexes} == {"zstd"}
    info = YAML(typ="safe").load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert (info["storage_identifier"], info["compression_format"], info["compression_mode"]) == ("mcap", "", "")
    got = rosbags_odometry(bag)
    for name in [n for n in ("ekf", "ukf") if f"/replay/{n}/odom" in got]:
        est = read_estimates(run_dir / "estimates" / f"{name}.csv.gz")
        ok = np.isfinite(est["x"][:, :2]).all(axis=1)
        np.testing.assert_array_equal(got[f"/replay/{name}/odom"][:, :2], est["x"][ok, :2])
    size, plain = sum(p.stat().st_size for p in bag.iterdir()), uncompressed_size(run_dir, tmp_path)
    assert size * ratio <= plain, (size, plain)
    return size, plain


def test_ros2_bag_compressed_as_ros2_bag_writes_it(run, tmp_path):
    check_compressed_bag(run / "ros2", run / "run", tmp_path)


@pytest.mark.slow
def test_test1_ros2_bag_a_third_of_the_uncompressed_size(shared_dir, tmp_path):
    """The issue's acceptance: the test1 export (robot_localization, gps-odom) reads back with rosbags
    and is at most 1/3 of the size the export had before (uncompressed chunks, 51.9 MB with the four
    default filters); measured: 5.0 MB."""
    bag = shared_dir / "datasets" / "bags" / "robot_localization" / "test1.bag"
    mapping = Path(__file__).resolve().parents[1] / "docs" / "mappings" / "rl_test1.toml"
    res = CliRunner().invoke(main, ["eval", str(bag), "--mapping", str(mapping), "--task", "gps-odom", "-f", "ekf",
                                    "-o", str(tmp_path / "r"), "--ros2-bag", str(tmp_path / "bag")],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.output
    size, plain = check_compressed_bag(tmp_path / "bag", tmp_path / "r", tmp_path)
    assert plain > 10e6 and size < plain / 5
    validate(tmp_path / "bag" / "bag.mcap")


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


# ---------------------------------------------------------------- the streamed writer: same file as before

def synthetic_run(n=3000, seed=5):
    """A frame, a problem and three filters' estimates with gaps, NaN cells and ties in time."""
    from types import SimpleNamespace

    from replay.frame import Channel, Frame

    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    truth = np.cumsum(rng.standard_normal((n, 3)), axis=0)
    dvl = rng.standard_normal((n, 3))
    dvl[rng.random(n) < 0.05, 1] = np.nan  # a NaN component in a valid row: JSON null
    frame = Frame(t, {"dvl": Channel(dvl, "m/s", components=("x", "y", "z"), valid=rng.random(n) < 0.9),
                      "depth": Channel(rng.standard_normal(n) + 10, "m", valid=np.arange(n) % 4 == 0)},
                  {"position": Channel(truth, "m")}, epoch=1.7e9)
    problem = SimpleNamespace(truth_position=truth, truth_valid=rng.random(n) < 0.8, position_index=(0, 1, 2),
                              axis_names=("x", "y", "z"), angle_index={}, model=SimpleNamespace(x_angles=(3,)))
    est = {}
    for i, m in enumerate((n, n, n - 700)):
        x = np.column_stack([truth[:m] + rng.standard_normal((m, 3)), np.zeros(m)])
        x[rng.random(m) < 0.02, 0] = np.nan  # a lost estimate: no pose at that step
        err = rng.standard_normal((m, 3))
        err[rng.random(m) < 0.1] = np.nan  # unscored steps
        est[f"f{i}"] = {"t": t[:m], "x": x, "P": np.full((m, 4), 0.5), "err": err}
    return frame, problem, est


def record_digest(path) -> str:
    """sha256 of every record after the magic, chunks opened: messages (channel, times, bytes),
    message indexes, chunk layout (times, sizes; no file offsets, which move with the schema
    bytes of the installed foxglove-schemas-protobuf), channels, statistics and header."""
    import hashlib

    from mcap.stream_reader import StreamReader

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for r in StreamReader(fh, validate_crcs=True).records:
            kind = type(r).__name__
            if kind == "Message":
                h.update(b"M%d,%d,%d,%d," % (r.channel_id, r.sequence, r.log_time, r.publish_time) + r.data)
            elif kind == "MessageIndex":
                h.update(b"I%d," % r.channel_id + repr(r.records).encode())
            elif kind == "ChunkIndex":
                h.update(b"C%d,%d,%d,%d" % (r.message_start_time, r.message_end_time, r.uncompressed_size,
                                            r.message_index_length))
            elif kind in ("Channel", "Statistics", "Header"):
                h.update(kind.encode() + repr(sorted(vars(r).items())).encode())
    return h.hexdigest()


def old_channels_digest(path) -> str:
    """sha256 of the messages (topic, times, bytes, in file order) of the channels an export had
    before the frame-transform and covariance channels (issue 16)."""
    import hashlib

    from mcap.reader import make_reader

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for _, ch, m in make_reader(fh).iter_messages(log_time_order=False):
            if not ch.topic.endswith(("/tf", "/covariance", "/tf_static", "/position_covariance")):
                h.update(b"%s,%d,%d,%d," % (ch.topic.encode(), m.log_time, m.publish_time, len(m.data)) + m.data)
    return h.hexdigest()


# write_mcap(synthetic_run()) with 64 KiB zstd chunks: the messages of the channels an export
# had before issue 16 (pose, path, error, sensors; 21,530), recorded at commit ae9ecba, whose
# record digest equalled that of the whole-file writer (commit 58d5cb4)
OLD_CHANNELS_DIGEST = "c767eaea1642e144982ed393c02fe13c0a6c3e8e244702b73b086ecc5fd1ffb6"
# and the whole file with the tf, covariance and /tf_static channels (40,243 messages, 89 chunks,
# digest f23a9000...), and since issue 24 the position_covariance channels too (48,380 messages),
# recorded when they were added: the streamed writer must keep giving it for any window
REFERENCE_DIGEST = "74b3166a0cf5655770b20f26c4fd881c343af19dddefa00bfb33e3d18757b706"


@pytest.mark.slow  # over 1 s for the small window: the full suite runs it
@pytest.mark.parametrize("window", [1 << 16, 500])
def test_streamed_export_keeps_the_old_channels_and_the_file(tmp_path, window):
    from replay.outputs.export_mcap import write_mcap

    frame, problem, est = synthetic_run()
    path = tmp_path / "s.mcap"
    assert write_mcap(path, frame, problem, est, chunk_size=1 << 16, window=window) == 48380
    assert old_channels_digest(path) == OLD_CHANNELS_DIGEST
    assert record_digest(path) == REFERENCE_DIGEST
    assert [p.name for p in tmp_path.iterdir()] == ["s.mcap"]  # no temporary left


def test_window_does_not_change_the_file_and_bounds_what_is_held(tmp_path, monkeypatch):
    from replay.outputs import mcap_bulk
    from replay.outputs.export_mcap import write_mcap

    frame, problem, est = synthetic_run()
    write_mcap(tmp_path / "whole.mcap", frame, problem, est, window=10**9)
    held, flush = [], mcap_bulk.BulkWriter.flush

    def spy(self):
        held.append(sum(len(p[1]) for p in self.parts))
        return flush(self)

    monkeypatch.setattr(mcap_bulk.BulkWriter, "flush", spy)
    write_mcap(tmp_path / "win.mcap", frame, problem, est, window=2000)
    assert (tmp_path / "win.mcap").read_bytes() == (tmp_path / "whole.mcap").read_bytes()
    assert sum(held) == 48380 and len(held) > 10
    assert max(held) <= 2000 + 9 * 21  # a window, plus at most 9 messages per channel (21; window cut times)


def test_ned_task_exported_in_enu():
    from types import SimpleNamespace

    from replay.outputs.run_data import enu_axes, enu_yaw, ned, to_enu

    dr = SimpleNamespace(axis_names=("north", "east", "depth"), position_index=(0, 1, 2))
    p = np.array([[10.0, 2.0, 5.0]])
    assert to_enu(p, enu_axes(dr)).tolist() == [[2.0, 10.0, -5.0]]  # east, north, up
    assert ned(dr) and enu_yaw(np.array([0.0]), True)[0] == pytest.approx(np.pi / 2)  # heading north
    xy = SimpleNamespace(axis_names=("x", "y"), position_index=(0, 1))
    assert to_enu(p[:, :2], enu_axes(xy)).tolist() == [[10.0, 2.0, 0.0]] and not ned(xy)
    depth = SimpleNamespace(axis_names=("depth",), position_index=(0,))
    assert to_enu(p[:, :1], enu_axes(depth)).tolist() == [[0.0, 0.0, -10.0]]
