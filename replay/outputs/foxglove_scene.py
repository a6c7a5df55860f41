"""The Foxglove 3D channels of an export: covariance ellipsoids and the frame-transform tree.

Frames (Foxglove's 3D panel shows them under "Transforms"; its display frame is the root):

* ``map`` — the root: the local east-north-up frame of the run;
* ``enu`` — the frame id of the pose, path and fix channels (written before the tree
  existed); ``/tf_static`` holds one identity ``map -> enu`` transform at the first time,
  so both name the same frame;
* ``<track>/base_link`` — the body of each estimate (and of the reference): a
  ``foxglove.FrameTransform`` ``map -> <track>/base_link`` on ``/replay/<track>/tf`` at
  every pose (translation = position, rotation = the heading as a yaw quaternion, or none
  when the task estimates no heading), so that a model (URDF, glTF) can be attached to it.

Covariance: ``/replay/<filter>/covariance`` carries one ``foxglove.SceneUpdate`` per step
with one entity (id = the filter's name, frame ``map``: each update replaces the previous
ellipsoid) holding one ``SpherePrimitive``: centred on the estimate, its axes along the
eigenvectors of the position covariance (in ENU) and its diameters ``2 * sigma * sqrt``
of the eigenvalues (``sigma``: the scale, default 3, in the channel's metadata). An
axis the task does not estimate (z of a 2-D task) gets a thin diameter, :data:`THIN` of
the largest, so that the ellipse is drawn as a flat disc. The colour is the filter's
colour in the report (:mod:`replay.outputs.palette`), translucent. The covariance itself
(ENU, m², the thin variance of an absent axis included) is on
``/replay/<filter>/position_covariance``: its upper triangle ``ee, en, eu, nn, nu, uu``
at the same times. Both come from the full position covariance of the estimate (the
variances alone only for an output written before the covariances were kept).
"""

from __future__ import annotations

import numpy as np
from replay.outputs.palette import Palette
from replay.outputs.pb_columns import encode
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform

ROOT = "map"
THIN = 0.02  # diameter of an axis the task has no variance for, relative to the largest
ALPHA = 0.35  # opacity of the ellipsoids
SIGMA = 3.0  # default scale: semi-axes of 3 standard deviations


def body_frame(track: str) -> str:
    return f"{track}/base_link"


def rgba(hex_colour: str) -> tuple[float, float, float, float]:
    return tuple(int(hex_colour[k : k + 2], 16) / 255 for k in (1, 3, 5)) + (ALPHA,)


def colours(names) -> dict:
    """The report's colour of every filter (one page: all of them), as RGBA."""
    pal = Palette(list(names))
    return {n: rgba(pal.colour(n)) for n in names}


def enu_covariance(var, axes) -> np.ndarray:
    """(m, 3, 3) ENU covariances from the task's position variances ``var`` (m, d) (a
    diagonal covariance) or covariances (m, d, d); ``axes``: ``run_data.enu_axes``.

    An ENU axis the task lacks gets the thin variance (see the module docstring)."""
    var = np.asarray(var, float)
    cov = var if var.ndim == 3 else var[:, :, None] * np.eye(var.shape[1])
    S = np.zeros((3, cov.shape[1]))
    for i, (slot, sign) in enumerate(axes):
        S[slot, i] = sign
    out = S @ cov @ S.T
    absent = ~S.any(axis=1)
    if absent.any():
        biggest = np.max(np.diagonal(out, axis1=1, axis2=2), axis=1)
        for slot in np.flatnonzero(absent):
            out[:, slot, slot] = THIN**2 * biggest
    return out


UPPER_NAMES = ["ee", "en", "eu", "nn", "nu", "uu"]  # the ENU covariance's upper triangle, row by row


def upper(cov) -> np.ndarray:
    """(m, 6) upper triangles (:data:`UPPER_NAMES`) of (m, 3, 3) covariances: what the
    ``/replay/<filter>/position_covariance`` channel carries, the matrix of the ellipsoid."""
    i, j = np.triu_indices(3)
    return np.asarray(cov, float)[:, i, j]


def quat_from_matrix(R) -> np.ndarray:
    """(m, 4) unit quaternions (x, y, z, w) of rotation matrices (m, 3, 3) (Shepperd's method)."""
    R = np.asarray(R, float)
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    cand = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], 1)
    k = np.argmax(cand, axis=1)
    s = 2 * np.sqrt(np.maximum(cand[np.arange(len(R)), k], 1e-300))
    a, b, c = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
    d, e, f = R[:, 0, 1] + R[:, 1, 0], R[:, 0, 2] + R[:, 2, 0], R[:, 1, 2] + R[:, 2, 1]
    q = np.select(
        [k[:, None] == j for j in range(4)],
        [
            np.stack([a, b, c, s * s / 4], 1),
            np.stack([s * s / 4, d, e, a], 1),
            np.stack([d, s * s / 4, f, b], 1),
            np.stack([e, f, s * s / 4, c], 1),
        ],
    )
    return q / s[:, None]


def ellipsoids(cov, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """(diameters (m, 3), orientations (m, 4) x, y, z, w) of the ``sigma`` ellipsoids of ``cov`` (m, 3, 3).

    A diagonal covariance keeps the ENU axes (identity orientation, diameters in x, y, z
    order); otherwise the axes are the eigenvectors (a right-handed rotation)."""
    cov = np.asarray(cov, float)
    m = len(cov)
    size, quat = np.zeros((m, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (m, 1))
    diag = np.einsum("kii->ki", cov)
    plain = np.all(cov - diag[:, :, None] * np.eye(3) == 0, axis=(1, 2))
    size[plain] = 2 * sigma * np.sqrt(np.maximum(diag[plain], 0.0))
    if not plain.all():
        w, V = np.linalg.eigh(cov[~plain])
        V[:, :, 2] *= np.sign(np.linalg.det(V))[:, None]
        size[~plain] = 2 * sigma * np.sqrt(np.maximum(w, 0.0))
        quat[~plain] = quat_from_matrix(V)
    return size, quat


def _stamp(ns) -> dict:
    sec, nanos = np.divmod(np.asarray(ns, np.int64), 1_000_000_000)
    return {"timestamp.seconds": sec, "timestamp.nanos": nanos}


def plan_ellipsoids(out, topic: str, name: str, ns, pos, cov, ok, sigma: float, colour) -> None:
    """``/replay/<name>/covariance``: one SceneUpdate per row ``ok``; ``pos(rows)`` ENU positions,
    ``cov(rows)`` ENU covariances (:func:`enu_covariance`), taken when a window is written."""
    idx = np.flatnonzero(ok)
    if not len(idx):
        return

    def updates(sel):
        rows = idx[sel]
        p = pos(rows)
        size, q = ellipsoids(cov(rows), sigma)
        f = {**_stamp(ns[rows]), "frame_id": ROOT, "id": name}
        f.update({f"spheres.pose.position.{a}": p[:, i] for i, a in enumerate("xyz")})
        f.update({f"spheres.pose.orientation.{a}": q[:, i] for i, a in enumerate("xyzw")})
        f.update({f"spheres.size.{a}": size[:, i] for i, a in enumerate("xyz")})
        f.update({f"spheres.color.{a}": v for a, v in zip("rgba", colour)})
        return encode(SceneUpdate, {f"entities.{k}": v for k, v in f.items()}, len(sel)).flat()

    meta = {
        "sigma": f"{sigma:g}",
        "frame_id": ROOT,
        "what": "position covariance ellipsoid, semi-axes sigma standard deviations along the eigenvectors",
    }
    out.plan(out.proto_channel(topic, SceneUpdate, meta), ns[idx], updates)


def plan_transforms(out, topic: str, child: str, ns, pos, quat, ok) -> None:
    """``map -> child`` FrameTransforms at rows ``ok``; ``pos(rows)``, ``quat(rows)`` (x, y, z, w)."""
    idx = np.flatnonzero(ok)
    if not len(idx):
        return

    def transforms(sel):
        rows = idx[sel]
        p, q = pos(rows), quat(rows)
        f = {**_stamp(ns[rows]), "parent_frame_id": ROOT, "child_frame_id": child}
        f.update({f"translation.{a}": p[:, i] for i, a in enumerate("xyz")})
        f.update({f"rotation.{a}": q[:, i] for i, a in enumerate("xyzw")})
        return encode(FrameTransform, f, len(sel)).flat()

    out.plan(out.proto_channel(topic, FrameTransform), ns[idx], transforms)


def plan_static(out, t_ns: int, child: str) -> None:
    """``/tf_static``: the identity ``map -> child`` at ``t_ns`` (the first time of the file)."""
    one = np.zeros((1, 3))
    plan_transforms(
        out,
        "/tf_static",
        child,
        np.array([t_ns], np.int64),
        lambda rows: one,
        lambda rows: np.array([[0.0, 0.0, 0.0, 1.0]]),
        np.ones(1, bool),
    )
