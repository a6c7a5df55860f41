"""Trajectory alignment for absolute trajectory error (ATE).

Given estimated positions ``a`` (n, 3) and reference positions ``b`` (n, 3),
find the transform T minimising sum_i |b_i - T(a_i)|^2:

* ``none``  — identity;
* ``yaw``   — rotation about the vertical axis plus a translation (4 DOF: the
  unobservable directions of a visual-inertial or gravity-aligned system);
* ``se3``   — rotation and translation (6 DOF);
* ``sim3``  — rotation, translation and scale (7 DOF).

SE(3)/Sim(3) follow Umeyama (1991), "Least-squares estimation of transformation
parameters between two point patterns", IEEE TPAMI 13(4), eq. 38-42:

    mu_a, mu_b the means; Sigma = (1/n) sum (b_i - mu_b)(a_i - mu_a)' = U D V'
    S = diag(1, ..., 1, det(U) det(V))      (a proper rotation, eq. 39)
    R = U S V',  c = trace(D S) / sigma_a^2 (eq. 42; c = 1 for SE(3)),  t = mu_b - c R mu_a

The yaw case is the same problem restricted to rotations about z: with centred
horizontal coordinates, yaw = atan2(sum (a_x b_y - a_y b_x), sum (a_x b_x + a_y b_y)).
"""
from __future__ import annotations

import numpy as np

from replay.util.errors import ReplayError

ALIGNMENTS = ("none", "yaw", "se3", "sim3")


def umeyama(a: np.ndarray, b: np.ndarray, with_scale: bool = False):
    """(R, t, c) minimising sum |b_i - (c R a_i + t)|^2 (Umeyama 1991, eq. 38-42)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    mu_a, mu_b = a.mean(axis=0), b.mean(axis=0)
    da, db = a - mu_a, b - mu_b
    sigma = db.T @ da / len(a)
    U, D, Vt = np.linalg.svd(sigma)
    S = np.ones(len(D))
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[-1] = -1.0
    R = (U * S) @ Vt
    c = float((D * S).sum() / (da**2).sum(axis=1).mean()) if with_scale else 1.0
    return R, mu_b - c * R @ mu_a, c


def yaw_align(a: np.ndarray, b: np.ndarray):
    """(R, t, 1) with R a rotation about z (4-DOF alignment, closed form)."""
    mu_a, mu_b = a.mean(axis=0), b.mean(axis=0)
    da, db = a - mu_a, b - mu_b
    yaw = np.arctan2((da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0]).sum(),
                     (da[:, 0] * db[:, 0] + da[:, 1] * db[:, 1]).sum())
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.eye(a.shape[1])
    R[:2, :2] = [[c, -s], [s, c]]
    return R, mu_b - R @ mu_a, 1.0


def align(a: np.ndarray, b: np.ndarray, method: str = "none"):
    """Transform (R, t, c) of ``method`` (one of :data:`ALIGNMENTS`) taking ``a`` onto ``b``."""
    if method not in ALIGNMENTS:
        raise ReplayError(f"alignment {method!r}: expected one of {', '.join(ALIGNMENTS)}")
    d = a.shape[1]
    if method == "none" or len(a) < 2:
        return np.eye(d), np.zeros(d), 1.0
    if method == "yaw":
        return yaw_align(a, b)
    return umeyama(a, b, with_scale=method == "sim3")


def apply(R, t, c, a):
    """c R a_i + t for every row of ``a``."""
    return c * a @ R.T + t
