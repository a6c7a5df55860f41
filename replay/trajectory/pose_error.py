"""Absolute and relative pose errors (APE, RPE) and their statistics, as evo computes them.

Poses are (R, p) with R from the unit quaternion q. On matched poses (same index =
same time) of a reference (Q) and an estimate (P):

* **APE** — E_k = P_k^-1 Q_k (evo's ``ape_base``, Kümmerle et al. 2009);
* **RPE** — E_ij = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j) over pairs (i, j) (evo's ``rpe_base``,
  Sturm et al. 2012, TUM RGB-D).

The error of E = (R_E, t_E) for each pose relation (evo's ``PoseRelation``, ``-r``):

| relation | evo ``-r`` | error | unit |
|---|---|---|---|
| ``trans`` | ``trans_part`` | \\|t_E\\| (APE: \\|p_est - p_ref\\|) | m |
| ``point_distance`` | ``point_distance`` | APE: as ``trans``; RPE: \\| \\|p_j - p_i\\|_est - \\|p_j - p_i\\|_ref \\| | m |
| ``point_distance_error_ratio`` | same | RPE only: that difference in % of the reference distance (pairs of zero distance left out) | % |
| ``angle_deg``, ``angle_rad`` | same | rotation angle of R_E | deg, rad |
| ``rot`` | ``rot_part`` | \\|R_E - I\\|_F = 2 sqrt(2) sin(angle / 2) | - |
| ``full`` | ``full`` | \\|E - I_4\\|_F = sqrt(\\|R_E - I\\|_F^2 + \\|t_E\\|^2) | - |

Computed with quaternions over all poses at once (no 4x4 matrices).

**RPE pairs** (:func:`pairs`, evo's ``id_pairs_from_delta``; by default on the estimate,
on the reference with ``pairs_from_reference``):

| ``delta_unit`` | evo ``-u`` | consecutive pairs | ``all_pairs`` |
|---|---|---|---|
| ``f`` frames | ``f`` | (0, d), (d, 2d), ... | (i, i + d) for every i |
| ``m`` metres | ``m`` | from each start, the first pose whose path length from it reaches d | for every i, the pose whose path length from i is nearest to d, if within ``rel_tol`` d |
| ``d``, ``r`` deg, rad | ``d``, ``r`` | the first pose whose summed rotation angle from the start reaches d | every j > i whose direct angle to i is within d ± ``rel_tol`` d |
| ``s`` seconds (not in evo) | | the first pose at least d s after the start | for every i, the pose nearest to t_i + d, if within ``rel_tol`` d |

**Statistics** (:func:`statistics`, evo's ``get_all_statistics``): rmse, mean, median,
std (population, ddof = 0), min, max, sse (sum of squares).
"""  # noqa: E501 (Markdown tables)

from __future__ import annotations

import math

import numpy as np

from replay.trajectory import quat
from replay.util.errors import ReplayError

RELATIONS = ("trans", "rot", "full", "angle_deg", "angle_rad", "point_distance", "point_distance_error_ratio")
EVO_NAMES = {"trans_part": "trans", "rot_part": "rot"}  # evo's -r spellings accepted too
UNITS = {
    "trans": "m",
    "point_distance": "m",
    "point_distance_error_ratio": "%",
    "angle_deg": "deg",
    "angle_rad": "rad",
    "rot": "",
    "full": "",
}
DELTA_UNITS = ("f", "m", "d", "r", "s")
STATISTICS = ("rmse", "mean", "median", "std", "min", "max", "sse")
ROTATION_RELATIONS = ("rot", "full", "angle_deg", "angle_rad")
RPE_NEEDS_ORIENTATION = ("trans", "rot", "full", "angle_deg", "angle_rad")


def relation(name: str) -> str:
    """The canonical name of a pose relation (ours or evo's), or a one-line refusal."""
    name = EVO_NAMES.get(name, name)
    if name not in RELATIONS:
        raise ReplayError(
            f"pose relation {name!r}: expected one of {', '.join(RELATIONS)} "
            "(evo's trans_part and rot_part are accepted too)"
        )
    return name


def _need_q(q, what: str):
    if q is None:
        raise ReplayError(
            f"{what} needs orientations, and a trajectory has positions only (e.g. GNSS fixes): "
            "use -r trans (APE) or point_distance (RPE)"
        )


def _from_error(rel: str, q_e, t_norm) -> np.ndarray:
    if rel in ("trans", "point_distance"):
        return t_norm
    s = np.linalg.norm(q_e[:, :3], axis=1)  # sin(angle / 2) of a unit quaternion
    if rel == "rot":
        return 2.0 * math.sqrt(2.0) * s
    if rel == "full":
        return np.sqrt(8.0 * s**2 + t_norm**2)
    a = quat.angle(q_e)
    return np.degrees(a) if rel == "angle_deg" else a


def ape(*, p_ref, q_ref, p_est, q_est, relation: str = "trans") -> np.ndarray:
    """APE of matched poses for one pose relation (module docstring)."""
    if relation == "point_distance_error_ratio":
        raise ReplayError("pose relation point_distance_error_ratio is defined for the RPE only")
    t_norm = np.linalg.norm(np.asarray(p_est, float) - p_ref, axis=1)
    if relation in ("trans", "point_distance"):
        return t_norm
    _need_q(q_ref if q_est is not None else None, f"APE of {relation}")
    return _from_error(relation, quat.multiply(quat.conjugate(q_est), q_ref), t_norm)


def ape_axes(*, p_ref, p_est) -> np.ndarray:
    """Per-axis APE: p_est - p_ref in the reference frame (n, 3)."""
    return np.asarray(p_est, float) - p_ref


def _relative(p, q, i, j):
    """(t, q) of P_i^-1 P_j for index arrays i, j."""
    qi_inv = quat.conjugate(q[i])
    return quat.rotate(qi_inv, p[j] - p[i]), quat.multiply(qi_inv, q[j])


def rpe(*, p_ref, q_ref, p_est, q_est, i, j, relation: str = "trans"):
    """(errors, axes): RPE of the pairs (i[k], j[k]) for one pose relation; ``axes`` (m, 3) are
    t_E (the translation error in the reference's frame at i), or None for the point distances."""
    i, j = np.asarray(i, int), np.asarray(j, int)
    p_ref, p_est = np.asarray(p_ref, float), np.asarray(p_est, float)
    if relation in ("point_distance", "point_distance_error_ratio"):
        d_ref = np.linalg.norm(p_ref[i] - p_ref[j], axis=1)
        err = np.abs(d_ref - np.linalg.norm(p_est[i] - p_est[j], axis=1))
        if relation == "point_distance_error_ratio":
            nz = d_ref != 0
            err = err[nz] / d_ref[nz] * 100
        return err, None
    _need_q(q_ref if q_est is not None else None, f"RPE of {relation}")
    t_q, r_q = _relative(p_ref, q_ref, i, j)
    t_p, r_p = _relative(p_est, q_est, i, j)
    r_q_inv = quat.conjugate(r_q)
    dt = t_p - t_q
    t_norm = np.linalg.norm(dt, axis=1)
    axes = quat.rotate(r_q_inv, dt)
    q_e = quat.multiply(r_q_inv, r_p) if relation in ROTATION_RELATIONS else None
    return _from_error(relation, q_e, t_norm), axes


def accumulated_distances(p: np.ndarray) -> np.ndarray:
    """Path length from the first pose to each pose (evo's ``accumulated_distances``)."""
    return np.concatenate(([0.0], np.cumsum(np.linalg.norm(p[:-1] - p[1:], axis=1))))


def _consecutive(steps: np.ndarray, delta: float):
    ids, acc = [0], 0.0
    for k, s in enumerate(steps.tolist(), start=1):
        acc += s
        if acc >= delta:
            ids.append(k)
            acc = 0.0
    ids = np.array(ids)
    return ids[:-1], ids[1:]


def _nearest_ahead(D: np.ndarray, delta: float, tol: float):
    """For every i: the j > i minimising |(D[j] - D[i]) - delta| (first of ties), kept within tol."""
    n = len(D)
    i = np.arange(n - 1)
    hi = np.searchsorted(D, D[i] + delta, side="left")
    hi = np.clip(hi, i + 1, n - 1)
    for _ in range(2):  # settle hi as the first j > i with D[j] - D[i] >= delta, in floating point
        down = (hi > i + 1) & (D[np.maximum(hi - 1, 0)] - D[i] >= delta)
        hi = np.where(down, hi - 1, hi)
        up = (hi < n - 1) & (D[hi] - D[i] < delta)
        hi = np.where(up, hi + 1, hi)
    lo = np.maximum(hi - 1, i + 1)
    lo = np.maximum(np.searchsorted(D, D[lo], side="left"), i + 1)  # first index of a plateau
    e_lo, e_hi = np.abs(D[lo] - D[i] - delta), np.abs(D[hi] - D[i] - delta)
    j = np.where(e_lo <= e_hi, lo, hi)
    e = np.minimum(e_lo, e_hi)
    keep = e <= tol
    return i[keep], j[keep]


def pairs(*, p, q, t, delta: float, unit: str = "f", all_pairs: bool = False, rel_tol: float = 0.1):
    """Index arrays (i, j) of the RPE pairs (module docstring), or a one-line refusal when there are none."""
    if unit not in DELTA_UNITS:
        raise ReplayError(
            f"delta unit {unit!r}: expected one of {', '.join(DELTA_UNITS)} (frames, metres, degrees, radians, seconds)"
        )
    if not delta > 0:
        raise ReplayError(f"delta {delta}: expected a positive number")
    n = len(p)
    if unit == "f":
        if float(delta) != int(delta):
            raise ReplayError(f"delta {delta}: a number of frames must be an integer")
        d = int(delta)
        if all_pairs:
            i = np.arange(max(n - d, 0))
            i, j = i, i + d
        else:
            ids = np.arange(0, n, d)
            i, j = ids[:-1], ids[1:]
    elif unit in ("m", "s"):
        if unit == "m":
            D = accumulated_distances(np.asarray(p, float))
            steps = np.linalg.norm(np.diff(np.asarray(p, float), axis=0), axis=1)
        else:
            D = np.asarray(t, float) - t[0]
            steps = np.diff(np.asarray(t, float))
        i, j = _nearest_ahead(D, delta, delta * rel_tol) if all_pairs else _consecutive(steps, delta)
    else:
        _need_q(q, "an RPE delta in angle")
        bound = 180.0 if unit == "d" else math.pi
        if delta > bound:
            raise ReplayError(f"delta {delta} {'deg' if unit == 'd' else 'rad'}: a rotation angle is at most {bound:g}")
        rad = math.radians(delta) if unit == "d" else delta
        tol = rad * rel_tol
        if all_pairs:
            ii, jj = [], []
            for k in range(n - 1):
                a = quat.angle(quat.multiply(quat.conjugate(q[k]), q[k + 1 :]))
                m = np.flatnonzero((a >= rad - tol) & (a <= rad + tol)) + k + 1
                ii.append(np.full(len(m), k))
                jj.append(m)
            i, j = (np.concatenate(ii), np.concatenate(jj)) if ii else (np.zeros(0, int), np.zeros(0, int))
        else:
            steps = quat.angle(quat.multiply(quat.conjugate(q[:-1]), q[1:]))
            i, j = _consecutive(steps, rad)
    if not len(i):
        raise ReplayError(
            f"RPE: delta = {delta:g} ({unit}) gives no pose pair among {n} poses: try a smaller "
            "delta" + (" or a larger tolerance" if all_pairs and unit != "f" else "")
        )
    return np.asarray(i, int), np.asarray(j, int)


def statistics(errors) -> dict:
    """rmse, mean, median, std, min, max, sse of ``errors`` (evo's definitions; NaN when empty)."""
    e = np.asarray(errors, float)
    if not len(e):
        return {k: float("nan") for k in STATISTICS}
    sq = np.power(e, 2)
    return {
        "rmse": math.sqrt(np.mean(sq)),
        "mean": float(np.mean(e)),
        "median": float(np.median(e)),
        "std": float(np.std(e)),
        "min": float(np.min(e)),
        "max": float(np.max(e)),
        "sse": float(np.sum(sq)),
    }
