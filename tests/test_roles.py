"""One home for a sensor role (issue 34 item 7, issue 37 item 4): a role is one ``replay.roles.ROLES``
entry read by the adapters and the fusion task; a frame's inputs are typed ``SensorInput`` records.

Numbers asserted: a barometer role defined here (its own ``altitude`` field, +up) fused on a
generated 3-D frame gives the EKF of the built-in ``depth`` role fed the same data as -up
(equal to 1e-9 m), and holds the height the velocity input alone lets drift."""
import numpy as np
import pytest

from replay import roles
from replay.adapters.mapping import from_dict
from replay.filters import make_filter
from replay.frame import Channel, Frame
from replay.roles import ROLES, Component, Field, Role, SensorInput, as_meta, ordered
from replay.tasks.fusion import FusionTask
from replay.util.errors import ReplayError

BAROMETER = Role(
    "barometer",
    kinds=("pressure",),
    fields=("altitude",),
    fuse=("altitude",),
    own=(Field("altitude", (), (Component(0, 2, 1.0),), "r_depth"),),  # height: +up, no place in 2-D
    doc="barometric altitude",
)


def generated(rng, baro: str | None):
    """A 3-D run (60 s at 10 Hz): a turning, climbing body with a DVL (body velocity, its w biased
    by 0.05 m/s), an IMU (gyro, attitude) and, by ``baro``, a barometer (+up) or a depth sensor
    (-up, role depth) of the same readings; the true position is the reference."""
    t = np.arange(0, 60, 0.1)
    n = len(t)
    yaw = 0.05 * t
    up = 5 * np.sin(0.1 * t)
    pos = np.column_stack([20 * np.sin(0.05 * t), 20 * (1 - np.cos(0.05 * t)), up])
    body_vel = np.column_stack([np.ones(n), 0 * t, 0.5 * np.cos(0.1 * t) + 0.05])  # yaw = course: u = 1 m/s
    att = np.column_stack([0 * t, 0 * t, yaw])
    gyro = np.column_stack([0 * t, 0 * t, 0.05 + 0 * t])
    ch = {
        "dvl": Channel(body_vel + rng.normal(0, 0.02, (n, 3)), "m/s", "base_link", description="/dvl velocity"),
        "imu": Channel(gyro + rng.normal(0, 0.002, (n, 3)), "rad/s", "imu", description="/imu gyro"),
        "imu_attitude": Channel(att + rng.normal(0, 0.01, (n, 3)), "rad", "imu", description="/imu attitude"),
    }
    inputs = [
        SensorInput("velocity", "dvl", "/dvl (generated)", {"velocity": "dvl"}),
        SensorInput("imu", "imu", "/imu (generated)", {"gyro": "imu", "attitude": "imu_attitude"}),
    ]
    height = up + rng.normal(0, 0.05, n)
    if baro == "barometer":
        ch["baro"] = Channel(height, "m", "up", description="/baro altitude")
        inputs.append(SensorInput("barometer", "baro", "/baro (generated)", {"altitude": "baro"}))
    elif baro == "depth":
        ch["depth"] = Channel(-height, "m", "down", description="/pressure depth")
        inputs.append(SensorInput("depth", "depth", "/pressure (generated)", {"depth": "depth"}))
    ref = {"position": Channel(pos, "m", "ENU local", description="truth position")}
    return Frame(t, ch, ref, meta={"source": "generated"}, roles=tuple(inputs))


def ekf(problem):
    return make_filter("ekf").run(problem.model, problem.z, problem.x0, problem.P0).x


def test_a_barometer_is_one_role_entry(monkeypatch):
    task = FusionTask()
    with pytest.raises(ReplayError, match="generated: task fusion: baro: unknown role 'barometer'"):
        task.build(generated(np.random.default_rng(1), "barometer"), np.random.default_rng(0))
    monkeypatch.setitem(ROLES, "barometer", BAROMETER)  # the one entry
    baro = task.build(generated(np.random.default_rng(1), "barometer"), np.random.default_rng(0))
    depth = task.build(generated(np.random.default_rng(1), "depth"), np.random.default_rng(0))
    # dims = auto takes the 3-D state for it (its field has no place in a planar state), measured +up
    assert baro.model.nx == depth.model.nx == 12
    assert "baro.altitude" in baro.inputs and "depth.depth" in depth.inputs
    up = [p.model.sign[np.asarray(p.model.index) == 2] for p in (baro, depth)]  # the one column measuring up
    assert list(up[0]) == [1.0] and list(up[1]) == [-1.0]
    assert "task fusion: [channels] baro altitude: noise default r_depth = 0.01" in baro.notes
    x_baro, x_depth = ekf(baro), ekf(depth)
    np.testing.assert_allclose(x_baro, x_depth, rtol=0, atol=1e-9)  # the depth role's numbers, to rounding
    truth = np.asarray(baro.truth_position, float)
    z_err = np.sqrt(np.mean((x_baro[:, 2] - truth[:, 2]) ** 2))
    free = task.build(generated(np.random.default_rng(1), None), np.random.default_rng(0))
    free_err = np.sqrt(np.mean((ekf(free)[:, 2] - truth[:, 2]) ** 2))
    assert z_err < 0.1 and free_err > 5 * z_err, (z_err, free_err)  # w biased 0.05 m/s: 3 m over 60 s


def test_a_mapping_may_name_a_registered_role_and_its_fields(monkeypatch):
    entry = {"channels": {"b": {"topic": "/p", "role": "barometer", "fuse": ["altitude"]}}}
    with pytest.raises(ReplayError, match="unknown role 'barometer'"):
        from_dict(entry, "m.toml")
    monkeypatch.setitem(ROLES, "barometer", BAROMETER)
    mp = from_dict(entry, "m.toml")
    assert mp.entries[0].role == "barometer" and mp.entries[0].fusion == {"fuse": ["altitude"]}
    assert roles.default_role("pressure") == "depth"  # a declared role; the kind's default unchanged


def test_roles_are_one_table_and_serialise_as_the_manifest_did():
    assert list(ROLES) == ["gps", "odometry", "imu", "depth", "velocity", "pose"]
    assert {k: roles.default_role(k) for k in ("navsatfix", "odometry", "imu", "pressure", "twist", "pose")} == {
        "navsatfix": "gps", "odometry": "odometry", "imu": "imu", "pressure": "depth", "twist": "velocity",
        "pose": "pose"}
    assert roles.known_fields() == ("position", "attitude", "velocity", "rate", "gyro", "depth")
    assert roles.differential_fields() == ("position", "attitude")
    # a GPS fix's height is not fused in 3-D; a pose's is
    assert [c.state for c in ROLES["gps"].components("position", 3)] == [0, 1]
    assert [c.state for c in ROLES["pose"].components("position", 3)] == [0, 1, 2]
    assert ROLES["depth"].components("depth", 3) == (Component(0, 2, -1.0, False),)
    odom = roles.make_input("odometry", "odom", "/odom (nav_msgs/msg/Odometry)", {"velocity": "odom_velocity"},
                            True, fuse=["velocity"], noise={"rate": 0.1}, mount=[0.0, 0.0, 1.0])
    assert as_meta([odom]) == {"odometry": [{"entry": "odom", "source": "/odom (nav_msgs/msg/Odometry)",
                                             "declared": True, "channels": {"velocity": "odom_velocity"},
                                             "mount": [0.0, 0.0, 1.0], "fuse": ["velocity"],
                                             "noise": {"rate": 0.1}}]}
    none = SensorInput("none", "x", "")
    assert ordered([SensorInput("imu", "i", ""), none, SensorInput("gps", "g", "")])[0].entry == "g"


def test_a_role_without_recorded_covariance_takes_the_default(monkeypatch):
    from types import SimpleNamespace

    from replay.tasks.fusion_inputs import variance

    n = 4
    var = Channel(np.full((n, 3), 0.25), "(m/s)^2", "base_link", description="/dvl velocity_var")
    frame = SimpleNamespace(channels={"dvl_velocity_var": var})
    comps = ROLES["velocity"].components("velocity", 2)
    ok = np.ones(n, bool)
    v, how, rec = variance(frame, SensorInput("velocity", "dvl", ""), "velocity", "velocity", comps, {}, n, ok, 0.04)
    assert rec["source"] == "recorded" and np.all(v == 0.25)
    monkeypatch.setitem(ROLES, "dvl", Role("dvl", ("twist",), ("velocity",), ("velocity",), recorded_covariance=False))
    v, how, rec = variance(frame, SensorInput("dvl", "dvl", ""), "velocity", "velocity", comps, {}, n, ok, 0.04)
    assert rec == {"source": "default", "variance": 0.04} and np.all(v == 0.04) and how == "default r_velocity = 0.04"
