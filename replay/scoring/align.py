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

For trajectories (:mod:`replay.trajectory`, ``replay score``), as evo does it:

* ``scale`` — scale only (evo's ``-s`` without ``-a``): c of the Sim(3) fit, R = I, t = 0;
* ``n_to_align`` — the transform is fitted on the first N pairs only and applied to all
  (evo's ``--n_to_align``);
* ``strict`` — a point set whose cross-covariance has rank below d - 1 (all points on one
  spot or, for the horizontal yaw fit, all on one vertical line) leaves the rotation
  undetermined and is refused (evo raises there too) instead of returning some rotation;
* :func:`origin` — the rigid transform taking the first estimated pose onto the first
  reference pose (evo's ``--align_origin``): R = R_b0 R_a0', t = p_b0 - R p_a0.
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import ReplayError

ALIGNMENTS = ("none", "yaw", "se3", "sim3")
TRAJECTORY_ALIGNMENTS = (*ALIGNMENTS, "scale")  # accepted by align(); the ATE column offers ALIGNMENTS


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
    yaw = np.arctan2(
        (da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0]).sum(), (da[:, 0] * db[:, 0] + da[:, 1] * db[:, 1]).sum()
    )
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.eye(a.shape[1])
    R[:2, :2] = [[c, -s], [s, c]]
    return R, mu_b - R @ mu_a, 1.0


def align(a: np.ndarray, b: np.ndarray, method: str = "none", *, n_to_align: int | None = None, strict: bool = False):
    """Transform (R, t, c) of ``method`` (one of :data:`TRAJECTORY_ALIGNMENTS`) taking ``a`` onto ``b``,
    fitted on the first ``n_to_align`` rows (all when None); ``strict`` refuses a degenerate fit."""
    if method not in TRAJECTORY_ALIGNMENTS:
        raise ReplayError(f"alignment {method!r}: expected one of {', '.join(TRAJECTORY_ALIGNMENTS)}")
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = a.shape[1]
    if n_to_align is not None:
        if n_to_align < 1:
            raise ReplayError(f"n_to_align {n_to_align}: expected a positive number of poses")
        a, b = a[:n_to_align], b[:n_to_align]
    if method == "none":
        return np.eye(d), np.zeros(d), 1.0
    if strict:
        check_rank(a, b, method)
    elif len(a) < 2:
        return np.eye(d), np.zeros(d), 1.0
    if method == "yaw":
        return yaw_align(a, b)
    R, t, c = umeyama(a, b, with_scale=method in ("sim3", "scale"))
    if method == "scale":
        return np.eye(d), np.zeros(d), c
    return R, t, c


def check_rank(a: np.ndarray, b: np.ndarray, method: str) -> None:
    """Refuse (ReplayError) a point set on which ``method`` is undetermined (see the module docstring)."""
    n, d = a.shape
    if n < 2:
        raise ReplayError(f"{method} alignment needs at least 2 poses, got {n}")
    if method == "yaw":
        spread = np.ptp(a[:, :2], axis=0).max(initial=0) * np.ptp(b[:, :2], axis=0).max(initial=0)
        if not spread > 0:
            raise ReplayError("yaw alignment is undetermined: the aligned poses do not move horizontally")
        return
    sigma = (b - b.mean(axis=0)).T @ (a - a.mean(axis=0)) / n
    D = np.linalg.svd(sigma, compute_uv=False)
    if np.count_nonzero(D > np.finfo(float).eps) < d - 1:
        raise ReplayError(
            f"{method} alignment is undetermined: the {n} aligned positions lie on a line or "
            "a point (cross-covariance of rank < 2)"
        )


def origin(R_a0: np.ndarray, p_a0: np.ndarray, R_b0: np.ndarray, p_b0: np.ndarray):
    """(R, t, 1) taking the pose (R_a0, p_a0) onto (R_b0, p_b0): origin alignment."""
    R = np.asarray(R_b0, float) @ np.asarray(R_a0, float).T
    return R, np.asarray(p_b0, float) - R @ np.asarray(p_a0, float), 1.0


def apply(R, t, c, a):
    """c R a_i + t for every row of ``a``."""
    return c * a @ R.T + t
