"""A synthetic AUV recording as a ROS 2 bag (MCAP storage): DVL, pressure, IMU, reference pose.

No small redistributable real AUV bag with a DVL and a pressure sensor exists,
so tests and examples generate one. The vehicle runs a lawnmower survey at
``speed`` m/s and ``depth`` m (a slow sinusoidal depth change of ``depth_swing``
m on top), heading changing by smooth 180-degree turns every ``leg`` s.

Topics (standard ROS 2 types only; header stamps = log times + ``latency``):

| topic | type | rate | content |
|---|---|---|---|
| ``/dvl/twist`` | geometry_msgs/TwistWithCovarianceStamped | 5 Hz | body-frame velocity + N(0, sigma_dvl^2) |
| ``/pressure`` | sensor_msgs/FluidPressure | 4 Hz | p_atm + rho g depth + N(0, sigma_p^2) |
| ``/imu/data`` | sensor_msgs/Imu | 20 Hz | body rates + N(0, sigma_gyro^2), attitude (below), gravity |
| ``/reference/pose`` | geometry_msgs/PoseStamped | 10 Hz | true position (ENU, up = -depth) and heading |

Which channels carry noise: the DVL velocity (3 axes), the pressure, the gyro (3 axes) and the yaw.
Noise-free: the roll and pitch (always 0: the vehicle flies level), the acceleration, the reference.
The IMU message records no covariance (zeros), so a filter told the yaw's variance for the whole
attitude over-states the roll and pitch noise: its attitude innovations are far smaller than it
expects, and the NIS of the fusion task is below its band (``sim/auv-bag``, 20 runs with the
generator's noise declared: ANEES 3.12 consistent, ANIS 1.96 pessimistic; ``tests/test_fusion.py``).

``AUV_MAPPING`` (same as ``docs/mappings/auv.toml``) reads it back.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from replay.util.errors import ReplayError
from replay.util.params import Param, validate

from . import generator

AUV_MAPPING = {
    "time": "header",
    "channels": {
        "dvl": {"topic": "/dvl/twist", "type": "geometry_msgs/msg/TwistWithCovarianceStamped"},
        "depth": {"topic": "/pressure", "type": "sensor_msgs/msg/FluidPressure"},
        "imu": {"topic": "/imu/data", "type": "sensor_msgs/msg/Imu"},
    },
    "reference": {"position": {"topic": "/reference/pose", "type": "geometry_msgs/msg/PoseStamped"}},
    "params": {"water_density": 1025.0, "atmospheric_pressure": 101325.0},
}
T0_NS = 1_661_126_400 * 10**9  # 2022-08-22 00:00 UTC, the day of the Bohai recordings


def trajectory(t, speed=1.5, depth=10.0, depth_swing=2.0, leg=60.0):
    """True east, north, depth, heading, yaw rate at times t (s)."""
    turn = 20.0  # s per 180-degree turn
    phase = np.mod(t, leg)
    n_leg = np.floor(t / leg)
    in_turn = phase > leg - turn
    rate = np.where(in_turn, np.pi / turn, 0.0) * np.where(np.mod(n_leg, 2) == 0, 1.0, -1.0)
    dt = np.diff(t, prepend=t[0])
    heading = np.cumsum(rate * dt)
    east = np.cumsum(speed * np.cos(heading) * dt)
    north = np.cumsum(speed * np.sin(heading) * dt)
    d = depth + depth_swing * np.sin(2 * np.pi * t / 300.0)
    return east, north, d, heading, rate


PARAMS = (
    Param("duration", float, 120.0, "length of the recording", unit="s", low=0, low_open=True),
    Param("speed", float, 1.5, "survey speed", unit="m/s", low=0),
    Param("depth", float, 10.0, "mean depth", unit="m"),
    Param("depth_swing", float, 2.0, "amplitude of the slow (300 s) depth change", unit="m", low=0),
    Param("sigma_dvl", float, 0.02, "DVL velocity noise standard deviation", unit="m/s", low=0),
    Param("sigma_p", float, 50.0, "pressure noise standard deviation", unit="Pa", low=0),
    Param("sigma_gyro", float, 0.002, "gyro noise standard deviation", unit="rad/s", low=0),
    Param("sigma_yaw", float, 0.01, "IMU yaw noise standard deviation", unit="rad", low=0),
    Param("latency", float, 0.005, "log time minus header stamp", unit="s", low=0),
)


def make_bag(path, rng: np.random.Generator, **params) -> int:
    """Write the recording to ``path`` (a ROS 2 bag directory); returns messages written.

    ``params``: see :data:`PARAMS` (checked, defaults filled in).
    """
    # lazy: the bags adapter brings rosbags and mcap (~200 ms measured), and the dataset registry imports this module
    from replay.adapters.rosmsg import ATMOSPHERIC_PRESSURE, GRAVITY, WATER_DENSITY, rpy_to_quat  # noqa: PLC0415
    from replay.adapters.bags import BagOut  # noqa: PLC0415

    p = validate(PARAMS, params, "simulator replay.sim.auv_bag")
    duration, speed, depth, depth_swing = p["duration"], p["speed"], p["depth"], p["depth_swing"]
    sigma_dvl, sigma_p, sigma_gyro, sigma_yaw = p["sigma_dvl"], p["sigma_p"], p["sigma_gyro"], p["sigma_yaw"]
    latency = p["latency"]

    fine = np.arange(0.0, duration, 0.01)
    e, n, d, h, w = trajectory(fine, speed, depth, depth_swing)
    out = BagOut(path)
    T = out.T
    lat_ns = int(round(latency * 1e9))

    def at(rate_hz):
        idx = np.arange(0, len(fine), int(round(100 / rate_hz)))
        return idx, T0_NS + np.round(fine[idx] * 1e9).astype(np.int64)

    try:
        idx, ns = at(5)
        c = out.connection("/dvl/twist", "geometry_msgs/msg/TwistWithCovarianceStamped")
        vz = np.gradient(-d, fine)
        noise = rng.standard_normal((len(idx), 3)) * sigma_dvl
        for j, (i, s) in enumerate(zip(idx, ns)):
            tw = out.twist((speed + noise[j, 0], noise[j, 1], vz[i] + noise[j, 2]), (0, 0, w[i]))
            cov = np.zeros(36)
            cov[[0, 7, 14]] = sigma_dvl**2
            msg = T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                header=out.header(s, "dvl_link"),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=cov),
            )
            out.write(c, s + lat_ns, msg)
        idx, ns = at(4)
        c = out.connection("/pressure", "sensor_msgs/msg/FluidPressure")
        p = ATMOSPHERIC_PRESSURE + WATER_DENSITY * GRAVITY * d[idx] + rng.standard_normal(len(idx)) * sigma_p
        for s, pi in zip(ns, p):
            out.write(
                c,
                s + lat_ns,
                T["sensor_msgs/msg/FluidPressure"](
                    header=out.header(s, "pressure_link"), fluid_pressure=float(pi), variance=sigma_p**2
                ),
            )
        idx, ns = at(20)
        c = out.connection("/imu/data", "sensor_msgs/msg/Imu")
        gyro = rng.standard_normal((len(idx), 3)) * sigma_gyro
        yaw = h[idx] + rng.standard_normal(len(idx)) * sigma_yaw
        q = rpy_to_quat(np.column_stack([np.zeros(len(idx)), np.zeros(len(idx)), yaw]))
        for j, (i, s) in enumerate(zip(idx, ns)):
            out.write(
                c,
                s + lat_ns,
                T["sensor_msgs/msg/Imu"](
                    header=out.header(s, "imu_link"),
                    orientation=out.quat(q[j]),
                    orientation_covariance=np.zeros(9),
                    angular_velocity=out.vec(gyro[j] + (0, 0, w[i])),
                    angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=out.vec((0, 0, GRAVITY)),
                    linear_acceleration_covariance=np.zeros(9),
                ),
            )
        idx, ns = at(10)
        c = out.connection("/reference/pose", "geometry_msgs/msg/PoseStamped")
        q = rpy_to_quat(np.column_stack([np.zeros(len(idx)), np.zeros(len(idx)), h[idx]]))
        for j, (i, s) in enumerate(zip(idx, ns)):
            out.write(
                c,
                s + lat_ns,
                T["geometry_msgs/msg/PoseStamped"](
                    header=out.header(s, "enu"), pose=out.pose((e[i], n[i], -d[i]), q[j])
                ),
            )
    finally:
        out.close()
    return out.count


@generator(PARAMS)
def make_frame(rng: np.random.Generator, **params):
    """Generate the bag in a temporary directory and read it with the ``bags`` adapter."""
    # lazy: as in make_bag
    from replay.adapters.bags import load  # noqa: PLC0415

    try:
        with tempfile.TemporaryDirectory() as tmp:
            make_bag(Path(tmp) / "auv", rng, **params)
            frame = load(Path(tmp) / "auv", mapping=AUV_MAPPING)
    except OSError as err:  # a full disk or a file-size limit while writing the temporary bag
        raise ReplayError(
            f"sim/auv-bag: cannot write its temporary bag in {tempfile.gettempdir()} ({err.strerror or err})"
        ) from None
    frame.meta["generator"] = "replay.sim.auv_bag:make_frame"
    frame.meta["source"] = "sim/auv-bag"  # not the temporary bag's path (gone, and machine-specific)
    frame.meta.pop("path", None)
    return frame
