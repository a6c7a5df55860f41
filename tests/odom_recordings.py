"""Generated odometry recordings with known truth (ROS 2 bags written by the project's own
``BagOut``), for the fusion task's identity tests (issue 34, items 1 and 3).

A vehicle moves with smooth body velocity and attitude; its nav_msgs/Odometry carries the true
pose (header frame ``odom``) and the true twist, in the body frame (``child_frame_id``, REP 105)
or, ``twist_in="parent"``, rotated into the odom frame (as some drivers publish it, with an empty
``child_frame_id``). Integrated on a 1 kHz grid (trapezoid), sampled at ``rate_hz``."""
from __future__ import annotations

import numpy as np

T0_NS = 1_700_000_000_000_000_000


def rotation(roll, pitch, yaw):
    from replay.models.kinematic import rotation as r

    return r(roll, pitch, yaw)


def motion(duration: float, dims: int):
    """Fine time (s), positions (n, 3), attitude (n, 3), body velocity (n, 3), body rates (n, 3)."""
    t = np.arange(0.0, duration + 1e-9, 1e-3)
    yaw = 1.2 + 0.6 * np.sin(0.08 * t)  # starts at 1.2 rad: a body twist and a world twist differ
    yaw_d = 0.6 * 0.08 * np.cos(0.08 * t)
    zero = np.zeros_like(t)
    if dims == 2:
        roll, pitch, roll_d, pitch_d = zero, zero, zero, zero
        vb = np.column_stack([1.5 + 0.3 * np.sin(0.05 * t), zero, zero])
    else:
        roll, roll_d = 0.05 * np.sin(0.3 * t), 0.05 * 0.3 * np.cos(0.3 * t)
        pitch, pitch_d = 0.05 + 0.1 * np.sin(0.2 * t), 0.1 * 0.2 * np.cos(0.2 * t)
        vb = np.column_stack([1.5 + 0.3 * np.sin(0.05 * t), 0.1 * np.sin(0.1 * t), 0.1 + zero])
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    rates = np.column_stack(  # the body rates of these Euler-angle rates (ZYX)
        [roll_d - yaw_d * sp, pitch_d * cr + yaw_d * sr * cp, -pitch_d * sr + yaw_d * cr * cp]
    )
    att = np.column_stack([roll, pitch, yaw])
    vw = np.einsum("kij,kj->ki", rotation(roll, pitch, yaw), vb)
    pos = np.vstack([np.zeros(3), np.cumsum((vw[1:] + vw[:-1]) / 2 * 1e-3, axis=0)]) + (10.0, -5.0, 2.0)
    return t, pos, att, vb, rates


def write_odometry_bag(path, *, dims=2, rate_hz=10.0, duration=60.0, child="base_link", twist_in="child"):
    """Write the recording (topic ``/odom``); returns the path length (m) of the sampled track."""
    from replay.adapters.bags import BagOut
    from replay.adapters.rosmsg import rpy_to_quat

    t, pos, att, vb, rates = motion(duration, dims)
    idx = np.arange(0, len(t), int(round(1000 / rate_hz)))
    R = rotation(att[idx, 0], att[idx, 1], att[idx, 2])
    v, w = vb[idx], rates[idx]
    if twist_in == "parent":
        v, w = np.einsum("kij,kj->ki", R, v), np.einsum("kij,kj->ki", R, w)
    q = rpy_to_quat(att[idx])
    out = BagOut(path)
    try:
        c = out.connection("/odom", "nav_msgs/msg/Odometry")
        for j, i in enumerate(idx):
            ns = T0_NS + int(round(t[i] * 1e9))
            out.write(c, ns, out.odometry(ns, "odom", child, pos[i], q[j], v[j], w[j]))
    finally:
        out.close()
    return float(np.linalg.norm(np.diff(pos[idx], axis=0), axis=1).sum())


def mapping(path, *, fuse='fuse = ["velocity", "rate"]', extra=""):
    """A mapping file: /odom fused alone (``fuse``), scored against its own recorded track."""
    path.write_text(
        "[channels]\n"
        f'odom = {{ topic = "/odom", type = "nav_msgs/msg/Odometry", {fuse}{extra} }}\n'
        "[reference]\n"
        'position = { topic = "/odom", type = "nav_msgs/msg/Odometry" }\n'
    )
    return path
