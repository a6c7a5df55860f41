"""Full covariances out (issue 24, item 5): the estimates file keeps the position covariance,
the campaign store the whole state's; the Foxglove ellipsoids are the eigen-decomposition of
the exported 3 x 3 covariance; the ROS 2 bag's 6 x 6 pose covariance is the estimate's.

On ``sim/auv-sonar`` the position covariance is strongly correlated (x with z through the
sonar's elevation), so an axis-aligned drawing would be wrong: the test asserts the correlation
first, so that it cannot pass on a diagonal case."""
import json

import numpy as np
import pytest
from click.testing import CliRunner
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader

from replay.cli import main
from replay.outputs import foxglove_scene as scene
from replay.outputs.run_data import read_estimates


def cli(*args, code=0):
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == code, res.output
    return res.output


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("cov")
    cli("eval", "sim/auv-sonar", "-f", "ekf,ukf", "--runs", "2", "--first", "60", "-o", out / "run", "-q")
    cli("export", out / "run", "--mcap", out / "run.mcap", "--ros2-bag", out / "bag")
    return out


def mcap_messages(path, topic):
    with open(path, "rb") as fh:
        return [(m.log_time, m.data) for _, _, m in make_reader(fh).iter_messages(topics=[topic])]


def test_estimates_file_keeps_the_position_covariance(run):
    est = read_estimates(run / "run" / "estimates" / "ukf.csv.gz")
    P = est["P"]
    assert est["full_covariance"] and P.shape == (60, 6, 6)
    d = np.sqrt(np.diagonal(P, axis1=1, axis2=2)[:, :3])
    corr = P[:, :3, :3] / (d[:, :, None] * d[:, None, :])
    assert np.abs(corr[:, [0, 0, 1], [1, 2, 2]]).max() > 0.5  # correlated: the drawing must be oriented
    np.testing.assert_array_equal(P[:, :3, :3], np.transpose(P[:, :3, :3], (0, 2, 1)))
    assert (P[:, 3:, 3:][:, ~np.eye(3, dtype=bool)] == 0).all()  # only the position block's pairs are kept


def test_ellipsoids_are_the_eigen_decomposition_of_the_exported_covariance(run):
    ups = mcap_messages(run / "run.mcap", "/replay/ukf/covariance")
    covs = mcap_messages(run / "run.mcap", "/replay/ukf/position_covariance")
    assert len(ups) == len(covs) == 60 and [t for t, _ in ups] == [t for t, _ in covs]
    est = read_estimates(run / "run" / "estimates" / "ukf.csv.gz")
    i, j = np.triu_indices(3)
    for k, ((_, up), (_, raw)) in enumerate(zip(ups, covs)):
        row = json.loads(raw)
        C = np.zeros((3, 3))
        C[i, j] = C[j, i] = [row[n] for n in scene.UPPER_NAMES]
        np.testing.assert_array_equal(C, est["P"][k, :3, :3])  # the exported covariance is the estimate's
        sph = SceneUpdate.FromString(up).entities[0].spheres[0]
        q = sph.pose.orientation
        x, y, z, w = q.x, q.y, q.z, q.w
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        size = np.array([sph.size.x, sph.size.y, sph.size.z])
        lam, V = np.linalg.eigh(C)
        order = np.argsort(size)
        # lengths: the sigma-scaled square roots of the eigenvalues; axes: the eigenvectors (up to sign)
        np.testing.assert_allclose(size[order], 2 * scene.SIGMA * np.sqrt(lam), rtol=1e-9)
        np.testing.assert_allclose(np.abs(np.sum(R[:, order] * V, axis=0)), 1.0, atol=1e-9)
        np.testing.assert_allclose(R @ np.diag((size / (2 * scene.SIGMA)) ** 2) @ R.T, C, rtol=1e-9,
                                   atol=1e-9 * np.abs(C).max())


def test_ros2_bag_pose_covariance_is_the_estimates(run):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    ts, got = get_typestore(Stores.ROS2_HUMBLE), []
    with Reader(run / "bag") as reader:
        for conn, _, raw in reader.messages():
            if conn.topic == "/replay/ekf/odom":
                got.append(np.asarray(ts.deserialize_cdr(raw, conn.msgtype).pose.covariance).reshape(6, 6))
    P = read_estimates(run / "run" / "estimates" / "ekf.csv.gz")["P"]
    assert len(got) == 60
    got = np.array(got)
    np.testing.assert_array_equal(got[:, :3, :3], P[:, :3, :3])  # sonar: x, y, z are east, north, up
    np.testing.assert_array_equal(got[:, 5, 5], P[:, 5, 5])  # yaw: anticlockwise from east, as estimated
    assert (got[:, 3:5] == 0).all() and (got[:, :, 3:5] == 0).all()  # roll and pitch of the body: not estimated
    assert np.abs(got[:, 0, 2]).max() > 0


def test_campaign_store_keeps_the_whole_state_covariance():
    """The per-step table of a unit (what the campaign store writes as Parquet) has every pair."""
    import replay
    from replay.util import covcols

    ev = replay.evaluate("sim/auv-sonar", filters=["ckf"], runs=1, first=30)
    res = ev.results[0]
    series, est = res.records[0].series, res.estimates[0]
    assert sum(k.startswith("P") and "_" in k for k in series) == 15  # 6 states: every pair
    back, full = covcols.matrices(series, 6)
    assert full and np.array_equal(back, est.P)
    back, full = covcols.matrices({k: v for k, v in series.items() if "_" not in k}, 6)  # an older table
    assert not full and np.array_equal(back, est.P * np.eye(6))
