"""Unit quaternions in numpy, ``(..., 4)`` arrays in ROS order ``x, y, z, w`` (Hamilton convention).

A quaternion q rotates a vector v as q v q*: the rotation matrix of a body whose
orientation is q takes body-frame vectors into the parent frame (ROS
``geometry_msgs/Quaternion``, TUM files). Every function acts on all leading axes at once.
"""

from __future__ import annotations

import numpy as np


def normalize(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def conjugate(q: np.ndarray) -> np.ndarray:
    """q* (the inverse of a unit quaternion)."""
    return np.asarray(q, float) * np.array([-1.0, -1.0, -1.0, 1.0])


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a b (first b, then a, as for rotation matrices A B)."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, float), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, float), -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """q v q* for unit quaternions ``q`` (..., 4) and vectors ``v`` (..., 3)."""
    q, v = np.asarray(q, float), np.asarray(v, float)
    u, w = q[..., :3], q[..., 3:]
    c = 2.0 * np.cross(u, v)
    return v + w * c + np.cross(u, c)


def to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions."""
    x, y, z, w = np.moveaxis(np.asarray(q, float), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) of rotation matrices (..., 3, 3) (the nearest rotation, by scipy)."""
    # lazy: start-up, scipy.spatial.transform measured ~790 ms
    from scipy.spatial.transform import Rotation  # noqa: PLC0415

    R = np.asarray(R, float)
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat().reshape(*R.shape[:-2], 4)


def angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle in [0, pi] of unit quaternions: 2 atan2(|v|, |w|) (accurate near 0 and pi)."""
    q = np.asarray(q, float)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


def slerp(a: np.ndarray, b: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Spherical interpolation from ``a`` (f = 0) to ``b`` (f = 1), the short way round."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    f = np.asarray(f, float)[..., None]
    d = np.einsum("...i,...i->...", a, b)[..., None]
    b = np.where(d < 0, -b, b)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-9
    wa = np.where(small, 1.0 - f, np.sin((1.0 - f) * theta) / np.where(small, 1.0, s))
    wb = np.where(small, f, np.sin(f * theta) / np.where(small, 1.0, s))
    return normalize(wa * a + wb * b)


def from_yaw(yaw: np.ndarray) -> np.ndarray:
    """Quaternions of rotations by ``yaw`` (rad) about z."""
    h = np.asarray(yaw, float) / 2.0
    z = np.zeros_like(h)
    return np.stack([z, z, np.sin(h), np.cos(h)], axis=-1)
