"""Sensor mountings from a recording's /tf_static (issue 34 item 1), as robot_localization applies
them: an IMU's rotation base_link -> imu_link, a GPS antenna's lever arm; a declared mount wins.

Numbers asserted, on a generated ROS 2 bag (odometry with the true pose and body velocity, an IMU
lying on its side as test1.bag's, /tf_static holding its mounting and a GPS antenna's): the
odometry velocity + the IMU gyro fused give the odometry's track back with the recorded mount
(EKF 0.03 m over a 68 m path) and the same numbers as the mount declared; without any mount the
gyro's z (the IMU's) holds no yaw rate and the track is lost (more than 10 m off); lever-arm
corrections undo a known antenna offset to 1e-9 m."""
import numpy as np
import pytest
from odom_recordings import T0_NS, motion, rotation

import replay
from replay import roles
from replay.adapters import bags
from replay.frame import Channel, Frame
from replay.roles import Mount, SensorInput
from replay.tasks.fusion_frames import lever_arm, mount_rotation
from replay.util import quat
from replay.util.errors import ReplayError

IMU_MOUNT = (np.pi / 2, 0.0, -np.pi / 2)  # test1.bag's IMU (robot_localization's test launch)
ARM = (0.8, -0.3, 1.1)  # the GPS antenna in base_link (m)


def write_bag(path, *, static=True, duration=40.0, rate_hz=20.0):
    """/odom (pose and body twist, child base_link), /imu (gyro and orientation in imu_link,
    mounted IMU_MOUNT), /fix (a NavSatFix in gps_link) and, with ``static``, /tf_static holding
    base_link -> imu_link and base_link -> gps_link (through a chain: base_link -> sensors ->
    gps_link)."""
    from replay.adapters.bags import BagOut
    from replay.adapters.rosmsg import rpy_to_quat

    t, pos, att, vb, rates = motion(duration, 2)
    idx = np.arange(0, len(t), int(round(1000 / rate_hz)))
    Rm = rotation(*IMU_MOUNT)
    q_body = rpy_to_quat(att[idx])
    R_imu = np.einsum("kij,jl->kil", rotation(att[idx, 0], att[idx, 1], att[idx, 2]), Rm)  # R_world_imu
    q_imu = quat.from_matrix(R_imu)
    gyro = rates[idx] @ Rm  # omega_imu = R_m' omega_body
    out = BagOut(path)
    T = out.T
    odom = out.connection("/odom", "nav_msgs/msg/Odometry")
    imu = out.connection("/imu", "sensor_msgs/msg/Imu")
    fix = out.connection("/fix", "sensor_msgs/msg/NavSatFix")
    if static:
        tf = out.connection("/tf_static", "tf2_msgs/msg/TFMessage")
        edges = [("base_link", "imu_link", (0.1, 0.0, 0.2), rpy_to_quat(np.array([IMU_MOUNT]))[0]),
                 ("base_link", "sensors", (0.5, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
                 ("sensors", "gps_link", np.subtract(ARM, (0.5, 0.0, 0.0)), (0.0, 0.0, 0.0, 1.0))]
        out.write(tf, T0_NS, T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
            header=out.header(T0_NS, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=out.vec(p), rotation=out.quat(q)))
            for parent, child, p, q in edges]))
    z3, zero9 = np.zeros(3), np.zeros(9)
    for j, i in enumerate(idx):
        ns = T0_NS + int(round(t[i] * 1e9))
        out.write(odom, ns, out.odometry(ns, "odom", "base_link", pos[i], q_body[j], vb[i], z3))
        out.write(imu, ns, T["sensor_msgs/msg/Imu"](
            header=out.header(ns, "imu_link"), orientation=out.quat(q_imu[j]), orientation_covariance=zero9,
            angular_velocity=out.vec(gyro[j]), angular_velocity_covariance=zero9,
            linear_acceleration=out.vec(z3), linear_acceleration_covariance=zero9))
        if j % 20 == 0:
            out.write(fix, ns, T["sensor_msgs/msg/NavSatFix"](
                header=out.header(ns, "gps_link"), status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
                latitude=42.0 + pos[i, 1] / 111_111.0, longitude=-71.0 + pos[i, 0] / 82_600.0, altitude=5.0,
                position_covariance=zero9, position_covariance_type=0))
    out.close()
    return float(np.linalg.norm(np.diff(pos[idx], axis=0), axis=1).sum())


def mapping(path, imu_extra=""):
    path.write_text(
        "[channels]\n"
        'odom = { topic = "/odom", fuse = ["velocity"] }\n'
        f'imu = {{ topic = "/imu", fuse = ["gyro"]{imu_extra} }}\n'
        "[reference]\n"
        'position = "/odom"\n'
    )
    return path


def ekf(bag, mp):
    ev = replay.evaluate(str(bag), dataset_params={"mapping": str(mp)}, filters=["ekf"], task="fusion", recorded=(),
                         runs=1)
    return ev.rows[0]["pos_rmse"], ev.results[0].records[0].problem.notes


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    d = tmp_path_factory.mktemp("mounts")
    path = write_bag(d / "with_tf")
    write_bag(d / "without_tf", static=False)
    return d, path


def test_the_adapter_reads_the_mountings_through_the_static_tree(recorded):
    d, _ = recorded
    f = bags.load(d / "with_tf", mapping={"channels": {"odom": "/odom", "imu": "/imu", "gps": "/fix"}})
    by = {i.entry: i for i in f.roles}
    assert by["odom"].recorded_mount is None  # an odometry has no mounting (Role.mount None)
    m = by["imu"].recorded_mount
    assert (m.parent, m.child) == ("base_link", "imu_link")
    np.testing.assert_allclose(m.rotation, IMU_MOUNT, atol=1e-9)
    np.testing.assert_allclose(m.translation, (0.1, 0.0, 0.2), atol=1e-12)
    g = by["gps"].recorded_mount  # composed base_link -> sensors -> gps_link
    assert (g.parent, g.child) == ("base_link", "gps_link")
    np.testing.assert_allclose(g.translation, ARM, atol=1e-12)
    assert roles.as_meta(f.roles)["imu"][0]["recorded_mount"]["child"] == "imu_link"
    lines = [e.reason for e in f.report.entries if e.what == "imu"]
    assert any(r.startswith("/tf_static: mounting base_link -> imu_link: rotation [1.5708, 0, -1.5708]")
               for r in lines), lines
    plain = bags.load(d / "without_tf", mapping={"channels": {"imu": "/imu"}})
    assert plain.roles[0].recorded_mount is None


def test_recorded_imu_mount_applied_and_equal_to_the_declared_one(recorded):
    d, path_m = recorded
    got, notes = ekf(d / "with_tf", mapping(d / "m.toml"))
    assert got < 0.2 and got < 0.005 * path_m, (got, path_m)  # the odometry's track back
    assert ("task fusion: [channels] imu gyro: mount from /tf_static base_link -> imu_link = "
            "[1.570796327, 0.0, -1.570796327]: rotated into the body frame") in notes
    declared = "mount = [1.5707963267948966, 0.0, -1.5707963267948966]"
    same, notes_d = ekf(d / "without_tf", mapping(d / "md.toml", ", " + declared))
    assert same == pytest.approx(got, rel=1e-9, abs=1e-9)
    lost, notes_n = ekf(d / "without_tf", mapping(d / "mn.toml"))
    assert lost > 10, lost  # the IMU's z holds no yaw rate: the heading is never turned
    assert "task fusion: [channels] imu gyro: no mount declared: the sensor's axes are the body's" in notes_n


def test_a_declared_mount_wins_and_the_conflict_is_one_note(recorded):
    d, _ = recorded
    _, notes = ekf(d / "with_tf", mapping(d / "mc.toml", ", mount = [1.570796327, 0.0, 0.0]"))
    said = [n for n in notes if "imu gyro: mount" in n]
    assert said == ["task fusion: [channels] imu gyro: mount = [1.570796327, 0.0, 0.0] declared (it differs from "
                    "/tf_static base_link -> imu_link = [1.570796327, 0.0, -1.570796327] by 1.57 rad; declared "
                    "wins): rotated into the body frame"], notes


def test_lever_arm_moves_fixes_to_the_body_origin_where_the_heading_is_known():
    t = np.arange(0.0, 10.0, 0.07)
    yaw = 0.3 * t
    att = np.column_stack([0.02 + 0 * t, -0.01 + 0 * t, yaw])
    body = np.column_stack([np.cos(0.3 * t), np.sin(0.3 * t), 0 * t]) * 5
    antenna = body + np.einsum("kij,j->ki", rotation(att[:, 0], att[:, 1], att[:, 2]), ARM)
    frame = Frame(t, {"fix": Channel(antenna, "m")})
    ok = np.ones(len(t), bool)
    rec = Mount((0.0, 0.0, 0.0), ARM, "base_link", "gps_link")
    gps = SensorInput("gps", "fix", "/fix (sensor_msgs/msg/NavSatFix)", {"position": "fix"}, recorded_mount=rec)
    att_ok = ok.copy()
    att_ok[40:56] = False  # 1.12 s without attitude: rows 47, 48 have none within 0.5 s (0.56 s away)
    moved, valid, note = lever_arm(frame, gps, antenna, ok, (att, att_ok, "imu"), "[channels] fix")
    np.testing.assert_allclose(moved[att_ok], body[att_ok], atol=1e-9)  # the attitude at the fix
    # next to the gap: the nearest attitude, up to 0.5 s old (yaw turns 0.15 rad: |arm| 0.85 m x 0.15)
    assert np.abs(moved[valid & ~att_ok] - body[valid & ~att_ok]).max() < 0.85 * 0.15
    assert list(np.flatnonzero(~valid)) == [47, 48]
    assert note == ("task fusion: [channels] fix position: lever arm from /tf_static base_link -> gps_link = "
                    "[0.8, -0.3, 1.1]: moved to the body origin by the attitude of imu; 2 fixes without an "
                    "attitude within 0.5 s not used")
    same, _, note = lever_arm(frame, gps, antenna, ok, None, "[channels] fix")
    assert same is antenna and "NOT applied: no fused attitude input gives the heading" in note
    declared = SensorInput("gps", "fix", "", {"position": "fix"}, lever_arm=(0.0, 0.0, 0.0), recorded_mount=rec)
    kept, _, note = lever_arm(frame, declared, antenna, ok, (att, ok, "imu"), "[channels] fix")
    np.testing.assert_allclose(kept, antenna, atol=0)
    assert "lever_arm = [0.0, 0.0, 0.0] declared (it differs from /tf_static base_link -> gps_link" in note


def test_mount_rotation_sources():
    rec = Mount((0.1, 0.0, 0.0), (0.0, 0.0, 0.0), "base_link", "imu")
    assert mount_rotation(SensorInput("imu", "i", "")) == (None, "")
    assert mount_rotation(SensorInput("imu", "i", "", recorded_mount=rec))[0] == [0.1, 0.0, 0.0]
    close = SensorInput("imu", "i", "", mount=(0.1, 0.0, 0.0005), recorded_mount=rec)
    assert mount_rotation(close) == ([0.1, 0.0, 0.0005], "mount = [0.1, 0.0, 0.0005] declared")  # within 1 mrad


def test_lever_arm_declared_only_on_an_antenna(recorded):
    from replay.adapters.mapping import from_dict

    d, _ = recorded
    with pytest.raises(ReplayError, match=r"\[channels\] imu: lever_arm is for an antenna's fixes \(role gps; not imu\)"):
        bags.load(d / "with_tf", mapping={"channels": {"imu": {"topic": "/imu", "lever_arm": [1, 0, 0]}}})
    f = bags.load(d / "with_tf", mapping={"channels": {"gps": {"topic": "/fix", "lever_arm": [1, 0, 0]}}})
    assert f.roles[0].lever_arm == (1.0, 0.0, 0.0) and f.roles[0].recorded_mount.child == "gps_link"

    with pytest.raises(ReplayError, match=r"lever_arm must be \[x, y, z\]"):
        from_dict({"channels": {"g": {"topic": "/fix", "lever_arm": [1, 2]}}}, "m.toml")
    mp = from_dict({"channels": {"g": {"topic": "/fix", "lever_arm": [1, 2, 0.5]}}}, "m.toml")
    assert mp.entries[0].fusion == {"lever_arm": [1.0, 2.0, 0.5]}


def test_recorded_lever_arm_applied_with_the_fused_imu_attitude(recorded):
    d, _ = recorded
    (d / "g.toml").write_text('[channels]\nodom = { topic = "/odom", fuse = ["velocity"] }\n'
                              'imu = { topic = "/imu", fuse = ["gyro", "attitude"] }\ngps = "/fix"\n'
                              '[reference]\nposition = "/fix"\n')
    _, notes = ekf(d / "with_tf", d / "g.toml")
    assert ("task fusion: [channels] gps position: lever arm from /tf_static base_link -> gps_link = "
            "[0.8, -0.3, 1.1]: moved to the body origin by the attitude of imu (/imu (sensor_msgs/msg/Imu))") in notes
    assert ("task fusion: [channels] imu attitude: mount from /tf_static base_link -> imu_link = "
            "[1.570796327, 0.0, -1.570796327]: rotated into the body frame") in notes
    (d / "g2.toml").write_text((d / "g.toml").read_text().replace('"gyro", "attitude"', '"gyro"'))
    _, notes = ekf(d / "with_tf", d / "g2.toml")  # no fused attitude: the heading at the fixes is unknown
    assert any(n.startswith("task fusion: [channels] gps position: lever arm from /tf_static base_link -> "
                            "gps_link = [0.8, -0.3, 1.1] NOT applied") for n in notes), notes
