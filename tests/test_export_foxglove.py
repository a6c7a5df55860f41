"""The Foxglove channels of an export (issue 16): frame-transform tree, covariance ellipsoids,
the manifest as MCAP metadata, the run chosen by --run, campaign directories chosen by flags,
recorded estimates exported as filters; and the ROS 2 bag compressed as `ros2 bag` does it.

Everything is decoded with the ``mcap`` reader and the generated protobuf classes and compared
with the run's own files (estimates, manifest, campaign units)."""
import json

import numpy as np
import pytest
from click.testing import CliRunner
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader
from test_export_mcap import synthetic_run, validate

from replay.cli import main
from replay.outputs import foxglove_scene as scene
from replay.outputs.run_data import read_estimates
from replay.util import covcols


def cli(*args, code=0):
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == code, res.output
    return res.output


def messages(path, topic, cls):
    with open(path, "rb") as fh:
        return [(m.log_time, cls.FromString(m.data)) for _, _, m in make_reader(fh).iter_messages(topics=[topic])]


def summary(path):
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        s = reader.get_summary()
        return s, {m.name: m.metadata for m in reader.iter_metadata()}


def ellipsoid_matrix(sphere, k):
    """The covariance drawn by a SpherePrimitive: R diag((size / 2k)^2) R^T, R its orientation."""
    q = sphere.pose.orientation
    x, y, z, w = q.x, q.y, q.z, q.w
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    s = np.array([sphere.size.x, sphere.size.y, sphere.size.z]) / (2 * k)
    return R @ np.diag(s ** 2) @ R.T


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("fox")
    cli("eval", "sim/auv-bag", "--task", "position", "-f", "ekf,ukf", "--first", "400", "--runs", "2",
        "-o", out / "run",
        "--mcap", out / "run.mcap")
    return out


def test_channels_schemas_counts_and_validator(run):
    s, _ = summary(run / "run.mcap")
    topics = {c.topic: s.schemas[c.schema_id].name for c in s.channels.values()}
    counts = {s.channels[k].topic: v for k, v in s.statistics.channel_message_counts.items()}
    for name in ("ekf", "ukf"):
        assert topics[f"/replay/{name}/tf"] == "foxglove.FrameTransform"
        assert topics[f"/replay/{name}/covariance"] == "foxglove.SceneUpdate"
        assert counts[f"/replay/{name}/tf"] == counts[f"/replay/{name}/covariance"] == counts[f"/replay/{name}/pose"] \
            == 400
    assert counts["/replay/reference/tf"] == counts["/replay/reference/pose"] == 200
    assert counts["/tf_static"] == 1 and counts["/replay/ekf/error"] == 200  # the error plots as before
    assert s.statistics.metadata_count == 2
    validate(run / "run.mcap")


def test_frame_transform_tree(run):
    poses = messages(run / "run.mcap", "/replay/ekf/pose", PoseInFrame)
    tfs = messages(run / "run.mcap", "/replay/ekf/tf", FrameTransform)
    assert len(tfs) == len(poses) == 400
    for (t1, p), (t2, f) in zip(poses, tfs):
        assert t1 == t2 and (f.parent_frame_id, f.child_frame_id) == ("map", "ekf/base_link")
        assert (f.translation.x, f.translation.y, f.translation.z) == (p.pose.position.x, p.pose.position.y,
                                                                          p.pose.position.z)
        assert f.rotation == p.pose.orientation and f.timestamp == p.timestamp
    ref = messages(run / "run.mcap", "/replay/reference/tf", FrameTransform)
    assert {(f.parent_frame_id, f.child_frame_id) for _, f in ref} == {("map", "reference/base_link")}
    [(t0, static)] = messages(run / "run.mcap", "/tf_static", FrameTransform)
    assert (static.parent_frame_id, static.child_frame_id) == ("map", "enu")  # the poses' frame id
    assert static.rotation.w == 1.0 and static.translation.x == 0.0 and t0 == poses[0][0]


@pytest.mark.parametrize("sigma", [None, 2.0])
def test_ellipsoid_axes_are_the_sigma_scaled_standard_deviations(run, sigma):
    path = run / "run.mcap"
    if sigma is not None:
        path = run / "sigma2.mcap"
        cli("export", run / "run", "--mcap", path, "--sigma", sigma)
    k = scene.SIGMA if sigma is None else sigma
    est = read_estimates(run / "run" / "estimates" / "ukf.csv.gz")
    ups = messages(path, "/replay/ukf/covariance", SceneUpdate)
    poses = messages(path, "/replay/ukf/pose", PoseInFrame)
    assert len(ups) == len(est["t"]) == 400
    size = np.array([[u.entities[0].spheres[0].size.x, u.entities[0].spheres[0].size.y,
                      u.entities[0].spheres[0].size.z] for _, u in ups])
    # sim/auv-bag: an isotropic covariance of east, north, up (off-diagonal ~1e-30): sizes = the variances
    np.testing.assert_allclose(np.sort(size, axis=1),
                               np.sort(2 * k * np.sqrt(np.diagonal(est["P"], axis1=1, axis2=2)[:, :3]), axis=1),
                               rtol=1e-12)
    np.testing.assert_allclose(np.array([ellipsoid_matrix(u.entities[0].spheres[0], k) for _, u in ups]),
                               est["P"][:, :3, :3], rtol=1e-9, atol=1e-9 * est["P"][:, :3, :3].max())
    e = ups[7][1].entities[0]
    assert (e.id, e.frame_id) == ("ukf", "map") and len(ups[7][1].entities) == 1
    sph = e.spheres[0]
    assert sph.pose.position == poses[7][1].pose.position and e.timestamp == poses[7][1].timestamp
    assert (sph.color.r, sph.color.g, sph.color.b) == pytest.approx(scene.rgba("#ff7f0e")[:3])  # the report's ukf
    s, _ = summary(path)
    meta = next(c.metadata for c in s.channels.values() if c.topic == "/replay/ukf/covariance")
    assert float(meta["sigma"]) == k


def test_metadata_holds_the_manifest(run):
    _, meta = summary(run / "run.mcap")
    text = (run / "run" / "manifest.json").read_text()
    assert meta["replay.manifest"] == {"manifest.json": text}
    assert json.loads(meta["replay.manifest"]["manifest.json"]) == json.loads(text)
    info = meta["replay.export"]
    assert info["run"] == "0" and json.loads(info["tracks"]) == ["reference", "ekf", "ukf", "measurements"]
    assert float(info["sigma"]) == scene.SIGMA


def test_run_flag_exports_that_run(run):
    out = cli("export", run / "run", "--run", 1, "--mcap", run / "r1.mcap")
    assert "run 1: ekf, ukf" in out
    est = read_estimates(run / "run" / "estimates" / "ekf.csv.gz", run=1)
    pos = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                    for _, p in messages(run / "r1.mcap", "/replay/ekf/pose", PoseInFrame)])
    assert np.array_equal(pos, est["x"][:, :3])
    assert not np.array_equal(est["x"], read_estimates(run / "run" / "estimates" / "ekf.csv.gz")["x"])
    assert summary(run / "r1.mcap")[1]["replay.export"]["run"] == "1"
    out = cli("export", run / "run", "--run", 2, "--mcap", run / "r2.mcap", code=2)
    assert "--run 2: it holds runs 0 to 1" in out and not (run / "r2.mcap").exists()
    out = cli("export", run / "run", "--dataset", "x", "--mcap", run / "r2.mcap", code=2)
    assert "--dataset choose among a campaign's configurations" in out


# ---------------------------------------------------------------- the geometry

def test_ellipsoids_of_a_full_covariance():
    rng = np.random.default_rng(4)
    A = rng.standard_normal((200, 3, 3))
    cov = A @ A.transpose(0, 2, 1) + 0.01 * np.eye(3)
    size, q = scene.ellipsoids(cov, 3.0)
    x, y, z, w = q.T
    R = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                  np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                  np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1, atol=1e-12)
    # axes along R's columns, diameters 2 * 3 * sqrt(eigenvalue): R diag(semi-axis / 3)^2 R' = cov
    D = ((size / 6) ** 2)[:, :, None] * np.eye(3)
    np.testing.assert_allclose(R @ D @ R.transpose(0, 2, 1), cov, atol=1e-10)
    np.testing.assert_allclose(np.sort(size, 1), 6 * np.sqrt(np.linalg.eigvalsh(cov)), rtol=1e-10)


def test_quaternions_of_half_turns():
    for axis in ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, -1, 0], [1, 1, 1], [0, -1, 1]):
        u = np.array(axis, float) / np.linalg.norm(axis)
        R = 2 * np.outer(u, u) - np.eye(3)  # a half turn about u: q = (u, 0) up to sign
        q = scene.quat_from_matrix(R[None])[0]
        assert abs(q[3]) < 1e-12 and abs(abs(q[:3] @ u) - 1) < 1e-12, axis


def test_enu_covariance_of_2d_and_ned_tasks():
    from types import SimpleNamespace

    from replay.outputs.run_data import enu_axes

    xy = enu_axes(SimpleNamespace(axis_names=("x", "y"), position_index=(0, 1)))
    size, q = scene.ellipsoids(scene.enu_covariance(np.array([[4.0, 1.0]]), xy), 1.0)
    assert size[0].tolist() == [4.0, 2.0, 4.0 * scene.THIN] and q[0].tolist() == [0, 0, 0, 1]  # a flat disc
    ned = enu_axes(SimpleNamespace(axis_names=("north", "east", "depth"), position_index=(0, 1, 2)))
    cov = np.array([[[4.0, 1.0, 0.5], [1.0, 9.0, 0.0], [0.5, 0.0, 1.0]]])
    enu = scene.enu_covariance(cov, ned)  # east, north, up = (x1, x0, -x2)
    assert enu[0].tolist() == [[9.0, 1.0, 0.0], [1.0, 4.0, -0.5], [0.0, -0.5, 1.0]]


# ---------------------------------------------------------------- recorded estimates, ROS 2 names

def test_recorded_estimate_exported_as_a_filter(tmp_path):
    from replay.outputs.export_mcap import write_mcap
    from replay.outputs.export_ros2 import ros_name, write_run_ros2

    frame, problem, est = synthetic_run(n=1000)
    x = est["f0"]["x"][:, :3]  # a recorded estimate: the position only, no heading column
    est = {"ekf": est["f1"], "recorded:gps": {"t": est["f0"]["t"], "x": x, "P": np.full((1000, 3), 0.25),
                                              "err": est["f0"]["err"]}}
    write_mcap(tmp_path / "r.mcap", frame, problem, est)
    tfs = messages(tmp_path / "r.mcap", "/replay/recorded:gps/tf", FrameTransform)
    assert len(tfs) == np.isfinite(x).all(axis=1).sum() and tfs[0][1].child_frame_id == "recorded:gps/base_link"
    assert tfs[0][1].rotation.w == 1.0  # no heading recorded: identity
    ups = messages(tmp_path / "r.mcap", "/replay/recorded:gps/covariance", SceneUpdate)
    assert ups[0][1].entities[0].spheres[0].size.x == pytest.approx(2 * scene.SIGMA * 0.5)
    validate(tmp_path / "r.mcap")
    assert ros_name("recorded:gps") == "recorded_gps" and ros_name("igwo-stcpf") == "igwo_stcpf"
    assert ros_name("3d--ekf") == "f_3d_ekf" and ros_name("ukf(alpha=0.5)") == "ukf_alpha_0_5"
    write_run_ros2({"frame": frame, "problem": problem, "estimates": est}, tmp_path / "bag")
    from replay.adapters import bags

    assert set(bags.read(tmp_path / "bag", []).topics) == {"/replay/reference/odom", "/replay/ekf/odom",
                                                         "/replay/recorded_gps/odom"}


# ---------------------------------------------------------------- campaign directories

CAMPAIGN = """\
[campaign]
name = "fox"
runs = 2
seed = 3
batch = 2

[[dataset]]
id = "sim/auv-sonar"
tasks = ["sonar"]
params = { steps = 30 }

[[dataset]]
id = "sim/lake-depth"
first = 200

[[filter]]
name = "ekf"

[[filter]]
name = "ukf"
grid = { alpha = [0.5, 1.0] }
"""


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    root = tmp_path_factory.mktemp("campaign")
    (root / "c.toml").write_text(CAMPAIGN)
    cli("campaign", "run", root / "c.toml", "-o", root / "out", "-w", 1, "-q")
    return root


def test_campaign_export_one_dataset_and_run(campaign):
    from replay.campaign.store import Store

    out = campaign / "out"
    text = cli("export", out, "--dataset", "sim/auv-sonar", "--run", 1, "--mcap", campaign / "c.mcap",
               "--ros2-bag", campaign / "bag")
    assert "run 1: ekf, ukf(alpha=0.5), ukf(alpha=1.0)" in text
    store = Store(out)
    hashes = {cfg["filter"] + str(cfg["filter_params"].get("alpha", "")): h for h, cfg in store.configs()
              if cfg["dataset"] == "sim/auv-sonar"}
    got = np.array([[p.pose.position.x, p.pose.position.y]
                    for _, p in messages(campaign / "c.mcap", "/replay/ukf(alpha=0.5)/pose", PoseInFrame)])
    want = store.series(hashes["ukf0.5"], 1)
    np.testing.assert_array_equal(got, np.column_stack([want["x0"], want["x1"]]))
    ups = messages(campaign / "c.mcap", "/replay/ekf/covariance", SceneUpdate)
    ekf = store.series(hashes["ekf"], 1)
    P, full = covcols.matrices(ekf, 6)
    assert full and abs(P[3, 0, 2]) > 0.1 * np.sqrt(P[3, 0, 0] * P[3, 2, 2])  # sonar: x and z correlated
    np.testing.assert_allclose(ellipsoid_matrix(ups[3][1].entities[0].spheres[0], scene.SIGMA), P[3, :3, :3],
                               rtol=1e-9, atol=1e-12)
    _, meta = summary(campaign / "c.mcap")
    man = meta["replay.manifest"]
    assert man["campaign.toml"] == (out / "campaign.toml").read_text()
    for h in hashes.values():
        assert json.loads(man[f"units/{h}/config.json"]) == json.loads((out / "units" / h / "config.json").read_text())
    assert json.loads(man["selection"]) == {"run": 1, "tracks": {"ekf": hashes["ekf"], "ukf(alpha=0.5)":
                                                                 hashes["ukf0.5"], "ukf(alpha=1.0)": hashes["ukf1.0"]}}
    validate(campaign / "c.mcap")
    from replay.adapters import bags

    assert "/replay/ukf_alpha_0_5/odom" in bags.read(campaign / "bag", []).topics


def test_campaign_selection_refusals(campaign):
    out, target = campaign / "out", campaign / "x.mcap"
    err = cli("export", out, "--mcap", target, code=2)
    assert "spans 2 datasets/tasks" in err and "--config" in err
    err = cli("export", out, "--task", "depth", "--run", 2, "--mcap", target, code=2)
    assert "run 2 of ekf is not stored; stored runs: 0 to 1" in err
    err = cli("export", out, "--filter", "pf", "--mcap", target, code=2)
    assert "no stored configuration matches --filter pf; stored: sim/auv-sonar sonar ekf" in err
    assert not target.exists()
    inside = out / "units" / "x.mcap"  # the campaign directory is an input: never written into
    err = cli("export", out, "--dataset", "sim/lake-depth", "--mcap", inside, code=2)
    assert "--mcap" in err and err.count("\n") == 1 and not inside.exists()
    h = next(p.name for p in (out / "units").iterdir())
    cli("export", out, "--config", h[:6], "--mcap", target)  # one configuration by its hash prefix
    s, _ = summary(target)
    assert len([c for c in s.channels.values() if c.topic.endswith("/covariance")]) == 1
