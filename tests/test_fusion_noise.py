"""The fusion task's noise (issue 34, items 2, 4, 5): recorded covariances as the default noise,
per-sensor outlier gating in every filter, and Bohai's forward velocity as an input (a recording
whose inputs constrain no speed is refused)."""
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from bohai_synth import write as write_bohai

import replay
from replay.adapters import rosmsg
from replay.adapters.mapping import from_dict
from replay.filters import make_filter
from replay.filters import kalman_kernels
from replay.filters.gating import Gate, Gates
from replay.frame import Channel
from replay.models.kinematic import Kinematic2D
from replay.roles import SensorInput
from replay.tasks.fusion_inputs import components, variance
from replay.util.errors import ReplayError
from pure import pure
import tomllib

MAPPINGS = Path(__file__).resolve().parents[1] / "docs" / "mappings"


# ---------------------------------------------------------------- recorded covariances

def test_converters_read_the_covariance_diagonals():
    """Odometry: 6x6 row-major pose and twist covariances (x, y, z at 0, 7, 14; rotations at 21,
    28, 35); Imu: three 3x3 (0, 4, 8); -1 and zeros kept raw for the task."""
    v3 = SimpleNamespace(x=0.0, y=0.0, z=0.0)
    q = SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0)
    pose_cov = np.arange(36.0) + 1
    odo = SimpleNamespace(header=SimpleNamespace(frame_id="odom"), child_frame_id="base_link",
                          pose=SimpleNamespace(pose=SimpleNamespace(position=v3, orientation=q), covariance=pose_cov),
                          twist=SimpleNamespace(twist=SimpleNamespace(linear=v3, angular=v3), covariance=-pose_cov))
    f = rosmsg.convert("odometry", [odo])
    assert f["position_var"][0].tolist() == [[1.0, 8.0, 15.0]]
    assert f["attitude_var"][0].tolist() == [[22.0, 29.0, 36.0]]
    assert f["velocity_var"][0].tolist() == [[-1.0, -8.0, -15.0]]
    assert f["rate_var"][0].tolist() == [[-22.0, -29.0, -36.0]]
    imu = SimpleNamespace(header=SimpleNamespace(frame_id="imu"), orientation=q, angular_velocity=v3,
                          linear_acceleration=v3, orientation_covariance=[-1.0] + [0.0] * 8,
                          angular_velocity_covariance=np.diag([1.0, 2.0, 3.0]).ravel(),
                          linear_acceleration_covariance=[0.0] * 9)
    f = rosmsg.convert("imu", [imu])
    assert f["gyro_var"][0].tolist() == [[1.0, 2.0, 3.0]]
    assert f["attitude_var"][0].tolist() == [[-1.0, 0.0, 0.0]] and f["accel_var"][0].tolist() == [[0.0, 0.0, 0.0]]


def _frame(var_rows):
    n = len(var_rows)
    ch = Channel(np.array(var_rows, float), "(m/s)^2", "base_link", np.ones(n, bool), ("x", "y", "z"),
                 description="/odom (nav_msgs/msg/Odometry) velocity_var")
    return SimpleNamespace(channels={"odom_velocity_var": ch})


def test_recorded_variance_per_message_bad_ones_replaced_and_counted():
    frame = _frame([[0.01, 0.02, 9], [0.0, 0.02, 9], [-1, 0.02, 9], [0.03, -0.5, 9], [np.nan] * 3])
    entry = SensorInput("odometry", "odom", "/odom (nav_msgs/msg/Odometry)")
    comps = components("velocity", 2, "odometry")  # u, v
    valid = np.array([True, True, True, True, False])
    var, how, rec = variance(frame, entry, "velocity", "velocity", comps, {}, 5, valid, 0.04)
    np.testing.assert_array_equal(var[:4], [[0.01, 0.02], [0.04, 0.02], [0.04, 0.04], [0.03, 0.04]])
    assert rec == {"source": "recorded", "channel": "/odom (nav_msgs/msg/Odometry) velocity_var",
                   "messages": 4, "replaced": 3, "default": 0.04}
    assert "3 of 4 messages had none usable" in how and "r_velocity = 0.04" in how
    var, how, rec = variance(frame, entry, "velocity", "velocity", comps, {"velocity": 0.5}, 5, valid, 0.04)
    assert (var == 0.5).all() and rec == {"source": "declared", "variance": 0.5}  # noise = {...} overrides
    all_bad = _frame([[0.0, 0, 0]] * 3)
    var, how, rec = variance(all_bad, entry, "velocity", "velocity", comps, {}, 3, np.ones(3, bool), 0.04)
    assert (var == 0.04).all() and rec["source"] == "default" and "all 3 messages" in how
    # a differential field: the recorded covariance is the pose's, not its change's
    var, how, rec = variance(frame, entry, "position", "velocity", comps, {}, 5, valid, 0.04)
    assert (var == 0.04).all() and rec["source"] == "default" and "differential" in how


def test_test1_uses_the_recorded_covariances(shared_dir):
    test1 = shared_dir / "datasets" / "bags" / "robot_localization" / "test1.bag"
    ev = replay.evaluate(str(test1), task="fusion", filters=["ekf"], runs=1, first=3000, recorded=(),
                         dataset_params={"mapping": str(MAPPINGS / "rl_test1_fusion.toml")})
    prob = ev.results[0].records[0].problem
    noise = ev.frame_meta["task_noise"]
    assert noise["odom.rate"] == {"source": "declared", "variance": 0.1}  # the mapping's noise = {rate = 0.1}
    assert noise["odom.velocity"]["source"] == noise["imu.gyro"]["source"] == "recorded"
    assert noise["gps.position"]["source"] == "recorded" and noise["gps.position"]["replaced"] == 0
    R, index, z = prob.model.R_steps, list(prob.model.index), prob.z
    u = index.index(3)  # u: the odometry twist's recorded covariance (the bag's 0.001)
    assert np.isfinite(z[:, u]).sum() > 300 and np.all(R[np.isfinite(z[:, u]), u] == 0.001)
    r = [j for j, i in enumerate(index) if i == 5]  # r: odometry declared 0.1, the gyro recorded 0.0004
    assert [set(np.unique(R[np.isfinite(z[:, j]), j])) for j in r] == [{0.1}, {0.0004}]


# ---------------------------------------------------------------- gating

def _gated_problem(gate: float | None, outliers=True, n=600, seed=3):
    """A 2-D vehicle at 1.5 m/s on a slow turn, 10 Hz body velocity and yaw rate, a 1 m fix every
    10th step; 12 of the 60 fixes moved 25-40 m (outliers)."""
    g = np.random.default_rng(seed)
    dt, r = 0.1, 0.02
    t = np.arange(n) * dt
    yaw = 0.2 + r * t
    speed = 1.5
    east = np.cumsum(speed * np.cos(yaw)) * dt
    north = np.cumsum(speed * np.sin(yaw)) * dt
    Z = np.full((n, 5), np.nan)
    fix = np.arange(0, n, 10)
    Z[fix, 0] = east[fix] + g.normal(0, 1, len(fix))
    Z[fix, 1] = north[fix] + g.normal(0, 1, len(fix))
    bad = fix[g.choice(np.arange(5, len(fix)), 12, replace=False)]
    if outliers:
        ang = g.uniform(0, 2 * np.pi, len(bad))
        dist = g.uniform(25, 40, len(bad))
        Z[bad, 0] += dist * np.cos(ang)
        Z[bad, 1] += dist * np.sin(ang)
    Z[:, 2] = speed + g.normal(0, 0.05, n)
    Z[:, 3] = g.normal(0, 0.05, n)
    Z[:, 4] = r + g.normal(0, 0.01, n)
    R = np.tile([1.0, 1.0, 0.0025, 0.0025, 1e-4], (n, 1))
    model = Kinematic2D(np.full(n, dt), np.array([0.01, 0.01, 0.01, 0.05, 0.05, 0.05]), [0, 1, 3, 4, 5],
                        [1.0] * 5, [], R)
    if gate is not None:
        model.gates = Gates(np.array([0, 0, 1, 1, 2], np.int64), np.array([gate, np.inf, np.inf]),
                            ("gps.position", "odom.velocity", "odom.rate"))
    x0 = np.array([0.0, 0.0, 0.2, speed, 0.0, r])
    P0 = np.diag([1.0, 1.0, 0.01, 0.1, 0.1, 0.01])
    truth = np.column_stack([east, north])
    return model, Z, x0, P0, truth, len(bad)


def _rmse(est, truth):
    return float(np.sqrt(np.mean(np.sum((est.x[:, :2] - truth) ** 2, axis=1))))


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf", "pf"])
def test_gating_rejects_injected_outliers_and_the_ungated_run_is_worse(name):
    """Each filter, gated at 5 (Mahalanobis), rejects exactly the 12 outlying fixes and none of the
    48 good ones; the same run without the gate is pulled further off. Position RMSE (m), gated /
    ungated / the same data without outliers: EKF 0.653 / 6.567 / 0.633, UKF 0.686 / 6.051 / 0.642,
    CKF 0.685 / 7.523 / 0.641, PF (500 particles, its optimal proposal: the gate judges f(x^i) with
    Q added) 0.685 / 2.485 / 0.620 (the bootstrap proposal: 1.216 / 2.874 / 2.988)."""
    flt = make_filter(name, **({"n_particles": 500} if name == "pf" else {}))
    model, Z, x0, P0, truth, n_bad = _gated_problem(5.0)
    gated = flt.run(model, Z, x0, P0, np.random.default_rng(0))
    free_model = _gated_problem(None)[0]
    free = flt.run(free_model, Z, x0, P0, np.random.default_rng(0))
    assert gated.info["rejected"] == {"gps.position": n_bad}
    assert "rejected" not in free.info
    e_gated, e_free = _rmse(gated, truth), _rmse(free, truth)
    clean = flt.run(_gated_problem(None, outliers=False)[0], _gated_problem(None, outliers=False)[1], x0, P0,
                    np.random.default_rng(0))
    if name == "pf":  # within 15 % of the run without outliers, the ungated run 3.6x worse
        assert e_gated < 1.15 * _rmse(clean, truth) and e_free > 3.0 * e_gated, (e_free, e_gated)
    else:  # as good as without the outliers (within 10 %), the ungated run 9-11x worse
        assert e_gated < 1.1 * _rmse(clean, truth) and e_free > 8.0 * e_gated, (e_free, e_gated)
    if name != "pf":  # the NIS leaves out the rejected components: its dof counts only the others
        fixes = np.isfinite(Z[:, 0])
        assert (gated.info["nis_dof"][fixes] == 5).sum() == fixes.sum() - n_bad


def test_a_gated_update_is_the_update_without_the_rejected_components():
    """The compiled update with a rejected group equals, to rounding, the update of the other
    components alone; its pure-Python source (tests/pure.py) gives the same numbers."""
    rng = np.random.default_rng(2)
    n, nz = 4, 3
    A = rng.standard_normal((1, n, n))
    P = A @ A.transpose(0, 2, 1) + np.eye(n)
    x = rng.standard_normal((1, n))
    H = rng.standard_normal((1, nz, n))
    R = np.diag([0.5, 0.5, 0.2])
    y = np.array([[40.0, -30.0, 0.3]])  # the first two (one group) far out
    group, limit2 = np.array([0, 0, 1], np.int64), np.array([9.0, np.inf])
    outs = []

    for fun in (kalman_kernels.joseph_update_gated, pure(kalman_kernels.joseph_update_gated)):
        xg, Pg, nis = x.copy(), P.copy(), np.empty(1)
        rej, cut = np.zeros((1, 2), np.int64), np.zeros(1, np.int64)
        assert fun(xg, Pg, y.copy(), H, R, np.zeros(n, bool), nis, Gate(group, limit2, rej, cut)) == -1
        assert rej.tolist() == [[1, 0]] and cut.tolist() == [2]
        outs.append((xg, Pg, nis))
    xr, Pr, nisr = x.copy(), P.copy(), np.empty(1)
    kalman_kernels.joseph_update(xr, Pr, y[:, 2:].copy(), H[:, 2:].copy(), R[2:, 2:].copy(), np.zeros(n, bool),
                                 nisr)
    for xg, Pg, nis in outs:
        np.testing.assert_allclose(xg, xr, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Pg, Pr, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(nis, nisr, rtol=1e-12)


def test_a_filter_that_does_not_gate_is_refused_on_a_gated_model():
    model, Z, x0, P0, _, _ = _gated_problem(5.0, n=200)
    with pytest.raises(ReplayError, match=r"gates its measurements \(rejection_threshold of gps.position\) and this filter does not implement"):
        make_filter("stckf").run(model, Z, x0, P0, np.random.default_rng(0))


@pytest.mark.parametrize("spec, message", [
    ("rejection_threshold = -1", "rejection_threshold must be a positive Mahalanobis distance"),
    ("rejection_threshold = { velocity = 0 }", "rejection_threshold.velocity must be a positive"),
    ('rejection_threshold = { sonar = 3 }', "unknown field 'sonar'"),
])
def test_bad_rejection_thresholds_refused(spec, message):
    doc = tomllib.loads(f'[channels]\nodom = {{ topic = "/odom", {spec} }}\n')
    with pytest.raises(ReplayError, match=message):
        from_dict(doc, "m.toml")


def test_rejection_threshold_round_trips_through_the_mapping():
    doc = tomllib.loads('[channels]\nodom = { topic = "/odom", rejection_threshold = 4 }\n'
                        'gps = { topic = "/fix", rejection_threshold = { position = 3.5 } }\n')
    mp = from_dict(doc, "m.toml")
    assert [e.fusion for e in mp.entries] == [{"rejection_threshold": 4.0},
                                              {"rejection_threshold": {"position": 3.5}}]
    assert [e.fusion for e in from_dict(tomllib.loads(mp.to_toml())).entries] == [e.fusion for e in mp.entries]


# ---------------------------------------------------------------- Bohai's forward velocity

def test_bohai_31_columns_fuse_the_forward_velocity(tmp_path):
    """The 31-column layout's vf (here the generated speed + N(0.006, 0.03) m/s) passes the
    adapter's check against the track and becomes a velocity input: gyro, attitude and vf dead-
    reckon the 600 m course to under 1 m (EKF 0.71 m, UKF 0.36 m at seed 0)."""
    path = write_bohai(tmp_path / "b31.csv", 31, "real")
    ev = replay.evaluate(str(path), adapter="bohai-csv", task="fusion", filters=["ekf", "ukf"], runs=1)
    prob = ev.results[0].records[0].problem
    assert set(prob.inputs) == {"vf.velocity", "gyro.gyro", "gyro.attitude", "reference"}
    fwd = ev.frame_meta["forward_velocity"]
    assert fwd["corr"] > 0.95 and abs(fwd["bias"] - 0.006) < 0.005
    assert all(r["pos_rmse"] < 1.0 for r in ev.rows), ev.rows


def test_bohai_without_a_speed_input_is_refused(tmp_path):
    """A 31-column file whose vf does not follow the track is dropped (named), and then nothing
    constrains the speed: the fusion task refuses in one line instead of ranking priors."""
    path = write_bohai(tmp_path / "b31.csv", 31, "noise")
    with pytest.raises(ReplayError) as err:
        replay.evaluate(str(path), adapter="bohai-csv", task="fusion", filters=["ekf"], runs=1)
    msg = str(err.value)
    assert "no input constrains the speed" in msg and "a velocity input" in msg and "\n" not in msg


def test_bohai_36_columns_keep_refusing_the_mislabelled_vf(tmp_path):
    """The 36-column files' vf (pos_accuracy under another name, up to tens of m/s) is dropped;
    the GPS fixes are the input that constrains the speed."""
    path = write_bohai(tmp_path / "b36.csv", 36, "garbage")
    ev = replay.evaluate(str(path), adapter="bohai-csv", task="fusion", filters=["ekf"], runs=1)
    assert "vf" in ev.frame_meta["dropped_columns"] and "velocity" not in ev.frame_meta.get("roles")
    assert set(ev.results[0].records[0].problem.inputs) == {
        "gps_position.position", "gyro.gyro", "gyro.attitude", "reference"}
    assert ev.rows[0]["pos_rmse"] < 1.0
