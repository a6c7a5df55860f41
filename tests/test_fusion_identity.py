"""Identity and agreement of the fusion task (issue 34, items 1 and 3).

One odometry fused alone (velocity + rate, or differential pose) and scored against its own
recorded track gives that track back: position RMSE at most 1 % of the path for the EKF, UKF and
CKF, which agree within 5 %; on generated recordings with known truth (tests/odom_recordings.py:
2-D and 3-D, 10 Hz and 100 Hz, with and without an empty child_frame_id) and on
robot_localization's test1.bag. The twist's frame: REP 105 (child_frame_id), or declared
(``twist_frame``); an empty child frame or a twist the pose contradicts is refused in one line."""
import dataclasses

import numpy as np
import pytest

from replay.roles import SensorInput

import replay
from odom_recordings import mapping, write_odometry_bag
from replay.util.errors import ReplayError

VR, DIFF = 'fuse = ["velocity", "rate"]', 'differential = ["position", "attitude"]'


def rmse(bag, mp, dims, filters=("ekf", "ukf", "ckf"), **kw):
    kw.setdefault("task_params", {"dims": str(dims)})
    ev = replay.evaluate(str(bag), dataset_params={"mapping": str(mp)}, filters=list(filters), task="fusion",
                         recorded=(), **kw)
    return {r["filter"]: r["pos_rmse"] for r in ev.rows}, ev


def assert_identity(by, path):
    for name, e in by.items():
        assert e <= 0.01 * path, (name, e, path)  # 1 % of the path
    # EKF, UKF, CKF agree within 5 % (or 0.05 % of the path: test1's differential CKF is 0.394 m
    # against the EKF's 0.414, 2 cm over 359 m, once its yaw variance has grown past pi^2 / 3)
    assert max(by.values()) - min(by.values()) <= max(0.05 * min(by.values()), 5e-4 * path), by


CASES = [
    pytest.param(dims, hz, fuse, child, marks=[pytest.mark.slow] if hz == 100 else [])
    for dims in (2, 3) for hz in (10, 100) for fuse in (VR, DIFF) for child in ("base_link", "")
]


@pytest.mark.parametrize("dims,hz,fuse,child", CASES)
def test_generated_odometry_alone_gives_its_track_back(tmp_path, dims, hz, fuse, child):
    """Known truth: 0.14 m (2-D) / 0.15 m (3-D) over 102 m at 10 Hz (forward Euler over 0.1 s
    steps), 0.014 / 0.015 m at 100 Hz; differential 0.21 / 0.21 and 0.021 / 0.022 m."""
    path = write_odometry_bag(tmp_path / "b", dims=dims, rate_hz=hz, child=child)
    declared = ', twist_frame = "child"' if not child else ""  # the default fuse adds the twist
    by, _ = rmse(tmp_path / "b", mapping(tmp_path / "m.toml", fuse=fuse, extra=declared), dims)
    assert_identity(by, path)
    assert max(by.values()) < (0.3 if hz == 10 else 0.03)  # the integration error of the rate, not more


@pytest.mark.parametrize("dims", [2, 3])
def test_parent_frame_twist_with_empty_child_refused_unless_declared(tmp_path, dims):
    path = write_odometry_bag(tmp_path / "b", dims=dims, child="", twist_in="parent")
    with pytest.raises(ReplayError) as err:
        rmse(tmp_path / "b", mapping(tmp_path / "m.toml"), dims, filters=("ekf",))
    msg = str(err.value)
    assert "\n" not in msg and "/odom" in msg and "empty child_frame_id" in msg and 'twist_frame = "child"' in msg
    by, ev = rmse(tmp_path / "b", mapping(tmp_path / "p.toml", extra=', twist_frame = "parent"'), dims)
    assert_identity(by, path)
    assert max(by.values()) < 0.3
    notes = ev.results[0].records[0].problem.notes
    assert any("twist_frame = parent declared: rotated" in n for n in notes)


def test_twist_contradicting_its_frame_refused(tmp_path):
    """A twist in the parent frame under a child_frame_id (or declared child), and a body twist
    declared parent: the pose's own course says otherwise, in one line naming the topic."""
    write_odometry_bag(tmp_path / "p", child="base_link", twist_in="parent")
    write_odometry_bag(tmp_path / "c", child="base_link", twist_in="child")
    for i, (bag, extra, said) in enumerate((("p", "", "child_frame_id is 'base_link'"),
                                            ("p", ', twist_frame = "child"', "twist_frame = 'child' is declared"),
                                            ("c", ', twist_frame = "parent"', "twist_frame = 'parent' is declared"))):
        with pytest.raises(ReplayError) as err:
            rmse(tmp_path / bag, mapping(tmp_path / f"{i}.toml", extra=extra), 2, filters=("ekf",))
        assert "\n" not in str(err.value) and "/odom" in str(err.value) and said in str(err.value)
    by, ev = rmse(tmp_path / "c", mapping(tmp_path / "ok.toml"), 2, filters=("ekf",))
    assert by["ekf"] < 0.3
    assert any("twist in child_frame_id 'base_link' (REP 105)" in n for n in ev.results[0].records[0].problem.notes)


def test_twist_frame_value_refused(tmp_path):
    write_odometry_bag(tmp_path / "b", duration=5.0)
    with pytest.raises(ReplayError, match=r'twist_frame must be "child" or "parent".*got \'body\''):
        rmse(tmp_path / "b", mapping(tmp_path / "m.toml", extra=', twist_frame = "body"'), 2, filters=("ekf",))


@pytest.fixture(scope="module")
def test1(shared_dir):
    return shared_dir / "datasets" / "bags" / "robot_localization" / "test1.bag"


@pytest.mark.slow
@pytest.mark.parametrize("fuse", [VR, DIFF])
def test_test1_odometry_alone_gives_its_track_back(test1, tmp_path, fuse):
    """Husky wheel odometry (359 m): EKF 0.692, UKF 0.692, CKF 0.694 m (velocity + rate; the UKF
    was 36.3 m and the CKF 37.5 m while their predicted mean was the points' mean), differential
    0.414, 0.414, 0.394 m (the UKF was 48.5 m)."""
    mp = tmp_path / "m.toml"
    mp.write_text(f'[channels]\nodom = {{ topic = "/husky_velocity_controller/odom", {fuse} }}\n'
                  '[reference]\nposition = "/husky_velocity_controller/odom"\n')
    by, ev = rmse(test1, mp, 2)
    ref = ev.results[0].records[0].problem.truth_position
    path = float(np.linalg.norm(np.diff(ref[np.isfinite(ref).all(axis=1)], axis=0), axis=1).sum())
    assert 355 < path < 365
    assert_identity(by, path)  # at most 3.6 m
    assert max(by.values()) < 0.75


# The PF estimates the posterior mean E[x | z]. With the noise a mapping declares by default (the
# task's q_attitude = 0.01 rad^2/s, the recorded or default twist variances) nothing measures the
# heading, so its posterior spread grows without bound (test1.bag: the EKF's own heading sd is
# 2.3 rad and its position sd 210 m after 395 s) and the mean of particles spread over such a
# heading is the track pulled inwards (40.3 and 44.3 m on test1.bag, 5 runs of 1000 particles): the Kalman
# filters' f(mean) gives the odometry's track back, not that posterior's mean. The identity is a
# property of a model that knows the heading: declared here, the PF gives the track back.
KNOWN = {"q_attitude": 1e-6, "r_velocity": 1e-4, "r_rate": 1e-6}  # the heading: integrated rate only
TIGHT = ", noise = { velocity = 1e-4, rate = 1e-6 }"  # the recorded twist covariances overridden


def assert_pf_identity(ev, path):
    """The PF's mean RMSE over runs, its 95 % Monte Carlo interval included, at most 1 % of the path."""
    row = next(r for r in ev.rows if r["filter"] == "pf")
    assert row["lost"] == 0 and row["runs"] >= 3
    assert row["pos_rmse"] + row["pos_rmse_ci95"] <= 0.01 * path, (row["pos_rmse"], row["pos_rmse_ci95"], path)
    return row


@pytest.mark.parametrize("dims,fuse", [(2, VR), (2, DIFF), (3, VR)])
def test_generated_odometry_alone_pf_gives_its_track_back(tmp_path, dims, fuse):
    """300 particles, the optimal proposal, 3 runs, 102 m: 0.20 m (2-D velocity + rate), 0.23 m
    (differential), 0.19 m (3-D) against the EKF's 0.17, 0.23, 0.17 m."""
    path = write_odometry_bag(tmp_path / "b", dims=dims)
    ev = replay.evaluate(str(tmp_path / "b"), dataset_params={"mapping": str(mapping(tmp_path / "m.toml", fuse=fuse, extra=TIGHT))},
                         filters=["ekf", "pf"], task="fusion", task_params={"dims": str(dims), **KNOWN}, recorded=(),
                         runs=3, filter_params={"pf": {"n_particles": 300}})
    row = assert_pf_identity(ev, path)
    assert row["pos_rmse"] < 0.3


@pytest.mark.slow
@pytest.mark.parametrize("fuse", [VR, DIFF])
def test_test1_odometry_alone_pf_gives_its_track_back(test1, tmp_path, fuse):
    """Husky wheel odometry (359 m), the heading known (KNOWN, TIGHT), 300 particles, 3 runs: PF
    0.83 m (velocity + rate) and 0.58 m (differential) where the EKF gives 0.70 and 0.43 m."""
    mp = tmp_path / "m.toml"
    mp.write_text(f'[channels]\nodom = {{ topic = "/husky_velocity_controller/odom", {fuse}{TIGHT} }}\n'
                  '[reference]\nposition = "/husky_velocity_controller/odom"\n')
    by, ev = rmse(test1, mp, 2, filters=("ekf", "pf"), runs=3, filter_params={"pf": {"n_particles": 300}},
                  task_params={"dims": "2", **KNOWN})
    assert by["ekf"] < 0.75
    assert_pf_identity(ev, 355.0)


@pytest.mark.slow
def test_test1_recorded_noise_leaves_the_heading_unknown(test1, tmp_path):
    """Why the PF's mean is not the odometry's track under the recorded covariances: the EKF's own
    covariance says the heading is unknown (sd 2.27 rad, position sd 210 m at the end)."""
    mp = tmp_path / "m.toml"
    mp.write_text(f'[channels]\nodom = {{ topic = "/husky_velocity_controller/odom", {VR} }}\n'
                  '[reference]\nposition = "/husky_velocity_controller/odom"\n')
    _, ev = rmse(test1, mp, 2, filters=("ekf",))
    pb = ev.results[0].records[0].problem
    P = replay.make_filter("ekf").run(pb.model, pb.z, pb.x0, pb.P0).P[-1]
    assert P[2, 2] > 2.0**2 and max(P[0, 0], P[1, 1]) > 100.0**2


@pytest.mark.slow  # compiles the sigma-point run loop when numba's cache lacks it
@pytest.mark.parametrize("name", ["ukf", "ckf"])
def test_mean_at_f_run_loop_equals_the_step_engine(tmp_path, name, monkeypatch):
    """The predicted mean f(mean) (Model.mean_at_f) in the compiled whole-run loop and in the
    step-by-step engine: the same numbers bit for bit."""
    from replay.filters import kalman, kalman_loops
    from replay.filters.compiled import loop_ready

    write_odometry_bag(tmp_path / "b", duration=20.0)
    _, ev = rmse(tmp_path / "b", mapping(tmp_path / "m.toml"), 2, filters=("ekf",))
    pb = ev.results[0].records[0].problem
    assert pb.model.mean_at_f and np.isfinite(pb.z).all()
    assert loop_ready(kalman_loops.sigma_run, kalman_loops.SIGMA_RUN, True)
    flt = replay.make_filter(name)
    used, real = [], kalman.run_kernels
    monkeypatch.setattr(kalman, "run_kernels", lambda *a: used.append(real(*a)) or used[-1])
    fast = flt.run(pb.model, pb.z, pb.x0, pb.P0)
    assert len(used) == 1 and isinstance(used[0], tuple)  # the loop ran
    monkeypatch.setattr(kalman, "run_kernels", lambda *a: None)
    slow = flt.run(pb.model, pb.z, pb.x0, pb.P0)
    assert np.array_equal(fast.x, slow.x) and np.array_equal(fast.P, slow.P)
    err = np.linalg.norm(slow.x[:, :2] - pb.truth_position[:, :2], axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.1



def imu_frame(yaw_sign=1.0, mount=None):
    """A frame of one IMU turning at 0.2 sin(0.5 t) rad/s about the body z for 30 s (20 Hz), its gyro and
    orientation seen through ``mount`` (the sensor's rotation in the body), its yaw reversed
    (``yaw_sign`` -1: NED-like) or not."""
    from types import SimpleNamespace

    from replay.models.kinematic import rotation as rot

    t = np.arange(0, 30, 0.05)
    body_att = np.column_stack([0 * t, 0 * t, 0.4 * (1 - np.cos(0.5 * t))])
    Rm = rot(*np.asarray(mount or (0, 0, 0), float))
    rate = np.column_stack([0 * t, 0 * t, 0.2 * np.sin(0.5 * t)])
    gyro = rate @ Rm  # omega_imu = R_m' omega_body
    R = np.einsum("kij,jl->kil", rot(*body_att.T), Rm)  # R_world_imu = R_world_body R_m
    att = np.column_stack([np.arctan2(R[:, 2, 1], R[:, 2, 2]), -np.arcsin(R[:, 2, 0]), np.arctan2(R[:, 1, 0], R[:, 0, 0])])
    att[:, 2] *= yaw_sign
    ch = SimpleNamespace(values=gyro, valid=np.ones(len(t), bool), description="imu gyro")
    entry = SensorInput("imu", "imu", "/imu (sensor_msgs/msg/Imu)", {"gyro": "imu"},
                        mount=tuple(mount) if mount else None)
    return SimpleNamespace(t=t, channels={"imu": ch}), entry, att


def test_imu_mount_rotates_gyro_and_attitude_into_the_body():
    from replay.tasks.fusion_frames import imu_yaw_sense, mounted

    mount = (np.pi / 2, 0.0, -np.pi / 2)  # test1.bag's IMU (robot_localization's test launch)
    frame, entry, att = imu_frame(mount=mount)
    gyro, note = mounted(entry, "gyro", frame.channels["imu"].values, "[channels] imu")
    np.testing.assert_allclose(gyro[:, :2], 0, atol=1e-12)
    np.testing.assert_allclose(gyro[:, 2], 0.2 * np.sin(0.5 * frame.t), atol=1e-12)
    assert "declared: rotated into the body frame" in note
    body, _ = mounted(entry, "attitude", att, "[channels] imu")
    np.testing.assert_allclose(body[:, :2], 0, atol=1e-9)
    np.testing.assert_allclose(np.angle(np.exp(1j * (body[:, 2] - 0.4 * (1 - np.cos(0.5 * frame.t))))), 0, atol=1e-9)
    ok = np.ones(len(frame.t), bool)
    assert "turns with the gyro's z (correlation 1.00" in imu_yaw_sense(frame, entry, body, ok, "w", "[channels] imu")
    entry = dataclasses.replace(entry, mount=None)  # not declared: the sensor's z is not the yaw axis; undecided, said
    assert "does not follow (undecided" in imu_yaw_sense(frame, entry, att, ok, "w", "[channels] imu")


def test_imu_yaw_turning_against_its_gyro_refused():
    from replay.tasks.fusion_frames import imu_yaw_sense

    frame, entry, att = imu_frame(yaw_sign=-1.0)
    with pytest.raises(ReplayError, match=r"^w: \[channels\] imu: /imu .*turns against .*correlation -1.00"):
        imu_yaw_sense(frame, entry, att, np.ones(len(frame.t), bool), "w", "[channels] imu")


def test_mount_refused_where_it_cannot_be(tmp_path):
    write_odometry_bag(tmp_path / "b", duration=5.0)
    for extra, msg in ((", mount = [1, 2]", r"mount must be \[roll, pitch, yaw\]"),
                       (", mount = [0, 0, 0.5]", r"mount is for an Imu \(not nav_msgs/msg/Odometry\)")):
        with pytest.raises(ReplayError, match=msg):
            rmse(tmp_path / "b", mapping(tmp_path / f"m{len(extra)}.toml", extra=extra), 2, filters=("ekf",))


def test_an_edited_mapping_is_read_again_in_the_same_process(tmp_path):
    """The frame of a file is read once per process while the file is unchanged; the mapping is part
    of what it is read with: rewritten (same path, same second), the next evaluation reads it again
    (it gave the first mapping's refusal)."""
    write_odometry_bag(tmp_path / "b", child="base_link", twist_in="parent")
    mp = mapping(tmp_path / "m.toml")
    with pytest.raises(ReplayError, match="child_frame_id is 'base_link'"):
        rmse(tmp_path / "b", mp, 2, filters=("ekf",))
    by, _ = rmse(tmp_path / "b", mapping(mp, extra=', twist_frame = "parent"'), 2, filters=("ekf",))
    assert by["ekf"] < 0.3


# Every shared recording with an odometry (../shared/datasets/bags/README.md; evo/ROS_example.bag has
# PoseStamped tracks only): (file, odometry topic, its path in m). test1.bag: above.
RECORDINGS = {
    "nav2_turtlebot": ("evo/nav2_turtlebot.mcap", "/odom", 34.32),
    "rl_test1_60s_mcap": ("derived/rl_test1_60s_mcap", "/husky_velocity_controller/odom", 58.23),
    "rl_test1_60s_sqlite3": ("derived/rl_test1_60s_sqlite3", "/husky_velocity_controller/odom", 58.23),
}


def own_track(shared_dir, tmp_path, file, topic, fuse, filters=("ekf", "ukf", "ckf")):
    """The odometry on ``topic`` fused alone and scored against its own recorded track: ({filter: RMSE}, path)."""
    mp = tmp_path / "m.toml"
    mp.write_text(f'[channels]\nodom = {{ topic = "{topic}", {fuse} }}\n[reference]\nposition = "{topic}"\n')
    by, ev = rmse(shared_dir / "datasets" / "bags" / file, mp, 2, filters=filters)
    ref = ev.results[0].records[0].problem.truth_position
    path = float(np.linalg.norm(np.diff(ref[np.isfinite(ref).all(axis=1)], axis=0), axis=1).sum())
    return by, path, ev


SLOW_READ = {"nav2_turtlebot"}  # 8 s in a fresh process (2 s once read)


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.slow] * (n in SLOW_READ)) for n in RECORDINGS])
@pytest.mark.parametrize("fuse", [VR, DIFF])
def test_shared_recording_odometry_alone_gives_its_track_back(shared_dir, tmp_path, name, fuse):
    """EKF = UKF = CKF to 1e-4 m: nav2_turtlebot.mcap (TurtleBot /odom, child base_footprint, 34.3 m)
    0.078 m (velocity + rate), 0.076 m (differential); the first 60 s of test1.bag as ROS 2 bags (MCAP and
    sqlite3 storage, 58.2 m) 0.426 m and 0.401 m, the same numbers from either storage."""
    file, topic, length = RECORDINGS[name]
    by, path, _ = own_track(shared_dir, tmp_path, file, topic, fuse)
    assert path == pytest.approx(length, abs=0.01)
    assert_identity(by, path)
    expect = {"nav2_turtlebot": (0.078, 0.076)}.get(name, (0.426, 0.401))[fuse == DIFF]
    assert max(by.values()) == pytest.approx(expect, abs=0.002), by


@pytest.mark.slow
def test_test3_groovy_odometry_has_no_track_to_give_back(shared_dir, tmp_path):
    """test3_groovy.bag (AR.Drone, 138 s) cannot give its odometry back: its /ardrone/odometry/raw pose
    never leaves x = y = 0 (25,217 messages; z is the altitude), its orientation quaternions are all
    zero (no attitude: a differential attitude is refused, 0 valid messages) and its twist's angular
    rates are all zero while the horizontal speed averages 0.58 m/s. Fused as velocity + rate, the
    filters integrate that twist (EKF = UKF = CKF: 15.25 m from a track of path 0.00 m): what the
    twist says and what the pose records are two different things, and the pose is no track."""
    topic = "/ardrone/odometry/raw"
    by, path, ev = own_track(shared_dir, tmp_path, "robot_localization/test3_groovy.bag", topic, VR)
    assert path < 1e-9  # the recorded pose does not move
    travelled = np.linalg.norm(np.diff(ev.results[0].estimates[0].x[:, :2], axis=0), axis=1).sum()
    assert travelled > 50.0 and all(v == pytest.approx(15.25, abs=0.05) for v in by.values()), (travelled, by)
    with pytest.raises(ReplayError, match=r"a differential attitude needs at least 2 messages \(got 0\)"):
        own_track(shared_dir, tmp_path, "robot_localization/test3_groovy.bag", topic, DIFF, filters=("ekf",))
