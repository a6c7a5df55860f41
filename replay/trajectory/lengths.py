"""Relative errors over sub-trajectory lengths, as rpg_trajectory_evaluation and the KITTI devkit define them.

``replay score --lengths 10%,20%,30%,40%,50%`` (or metres, ``--lengths 100,200,...,800``) computes,
for each length L, the error of the relative motion of sub-trajectories of (about) L metres of
the reference's path.

**Lengths** (:func:`parse`, :func:`resolve`): ``P%`` is P % of the path length of the whole
reference (all its poses, matched or not), truncated to 2 decimals as rpg does
(``trunc(100 * P/100 * length) / 100``); a plain number is metres. ``A,B,...,Z`` expands to the
arithmetic range A, B, B + (B - A), ... up to Z.

**Sub-trajectories** (start index i, end index j, on the matched poses, path length D of the
matched reference):

* ``rpg`` (default; rpg's ``compute_comparison_indices_length``): for each start pose, the end
  j >= start nearest to D[start] + L (first of ties), kept when strictly within 0.2 L. As in rpg,
  the k-th end found is paired with start k: the same as its own start unless some start in the
  middle of the track found no end (a gap in the poses), which is reported. Fewer than two ends:
  no sample (rpg: "Too few samples").
* ``kitti`` (the KITTI devkit's ``calcSequenceErrors``): every 10th pose is a start; the end is
  the first pose whose distance exceeds D[start] + L, with D accumulated and compared in single
  precision as the devkit's ``vector<float>``; starts without such a pose are skipped.

**Errors** (rpg's ``compute_relative_error``, with the scale s of the alignment and the
estimate's orientations as recorded; T = (R, t) poses, g reference, e estimate):
E = R_e,j (T_g,ij^-1 T_e,ij) R_e,j^-1 with T_x,ij = T_x,i^-1 T_x,j and t_e,ij scaled by s. Then
``trans`` = |t_E| (m), ``trans_perc`` = 100 |t_E| / L, ``rot`` = arccos((tr R_E - 1) / 2) in
degrees, ``rot_deg_per_m`` = rot / L, ``yaw`` = |yaw| and ``gravity`` = sqrt(pitch^2 + roll^2) (deg)
of R_E's z-y-x Euler angles. The KITTI devkit's error inv(T_e,ij) T_g,ij has the same translation
norm and angle (its t_err / L and r_err / L are ``trans_perc`` / 100 and ``rot_deg_per_m`` in rad);
yaw and gravity are rpg's. The alignment changes none of these numbers except through s (a
rigid motion of the estimate leaves every relative motion unchanged).

Statistics per length and error: rmse, mean, median, std, min, max, num_samples (rpg's
``compute_statistics``).
"""

from __future__ import annotations

import math

import numpy as np

from replay.trajectory import quat
from replay.util.errors import ReplayError

METHODS = ("rpg", "kitti")
ERRORS = ("trans", "trans_perc", "rot", "rot_deg_per_m", "yaw", "gravity")
UNITS = {"trans": "m", "trans_perc": "%", "rot": "deg", "rot_deg_per_m": "deg/m", "yaw": "deg", "gravity": "deg"}
RPG_MAX_DIFF = 0.2  # rpg: max_dist_diff = 0.2 * length
KITTI_STEP = 10  # devkit: step_size
MAX_LENGTHS = 100


def _item(tok: str, spec: str):
    pct = tok.endswith("%")
    try:
        v = float(tok[:-1] if pct else tok)
    except ValueError:
        raise ReplayError(
            f"--lengths {spec}: {tok!r} is neither a length in metres nor a percentage like 10%"
        ) from None
    if not (math.isfinite(v) and v > 0) or (pct and v > 100):
        raise ReplayError(f"--lengths {spec}: {tok!r} must be a positive length in metres or a percentage in (0, 100]%")
    return ("%" if pct else "m", v)


def parse(spec: str) -> list:
    """``[(unit, value)]`` with unit ``%`` or ``m`` from ``10%,20%`` or ``100,200,...,800`` (module docstring)."""
    toks = [t.strip() for t in str(spec).split(",")]
    if not toks or any(not t for t in toks):
        raise ReplayError(f"--lengths {spec!r}: expected a comma-separated list such as 10%,20%,30% or 100,200,...,800")
    out = []
    for k, tok in enumerate(toks):
        if tok != "...":
            out.append(_item(tok, spec))
            continue
        if k < 2 or k + 1 >= len(toks) or toks[k + 1] == "..." or toks[k - 1] == "...":
            raise ReplayError(f"--lengths {spec}: '...' needs two values before it and one after (100,200,...,800)")
        (u1, a), (u2, b) = out[-2], out[-1]
        u3, z = _item(toks[k + 1], spec)
        if not (u1 == u2 == u3) or not b > a or not z > b:
            raise ReplayError(f"--lengths {spec}: '...' needs increasing values of one unit around it")
        step, n = b - a, round((z - b) / (b - a))
        if abs(b + n * step - z) > 1e-9 * z:
            raise ReplayError(f"--lengths {spec}: {toks[k + 1]} is not on the step {step:g} from {toks[k - 1]}")
        if len(out) + n > MAX_LENGTHS:
            raise ReplayError(f"--lengths {spec}: more than {MAX_LENGTHS} lengths, at most {MAX_LENGTHS}")
        out += [(u1, b + m * step) for m in range(1, n)]
    if len(out) > MAX_LENGTHS:
        raise ReplayError(f"--lengths {spec}: {len(out)} lengths, at most {MAX_LENGTHS}")
    if len(set(out)) != len(out):
        raise ReplayError(f"--lengths {spec}: a length is given twice")
    return out


def label(unit: str, value: float) -> str:
    return f"{value:g}%" if unit == "%" else f"{value:g}m"


def resolve(items, path_length: float) -> list:
    """``[(label, metres)]``: percentages of ``path_length`` truncated to cm as rpg does; a refusal for 0 m."""
    out = []
    for unit, v in items:
        m = math.trunc(v / 100.0 * path_length * 100.0) / 100.0 if unit == "%" else float(v)
        if not m > 0:
            raise ReplayError(
                f"--lengths {label(unit, v)}: {m:g} m of a reference path of {path_length:g} m "
                "(percentages are truncated to cm, as rpg does): give a larger length"
            )
        out.append((label(unit, v), m))
    return out


def rpg_pairs(D: np.ndarray, length: float, max_diff: float):
    """(i, j, gaps): rpg's comparison indices (module docstring); ``gaps``: starts before the last
    found one that found no end (rpg then pairs ends with shifted starts)."""
    n = len(D)
    start = np.arange(n)
    target = D + length
    hi = np.searchsorted(D, target, side="left")  # first index with D >= target (>= start: length > 0)
    err_hi = np.where(hi < n, np.abs(D[np.minimum(hi, n - 1)] - target), np.inf)
    lo = hi - 1
    has_lo = lo >= start
    lo_first = np.maximum(np.searchsorted(D, D[np.maximum(lo, 0)], side="left"), start)
    err_lo = np.where(has_lo, np.abs(D[np.maximum(lo, 0)] - target), np.inf)
    best = np.where(err_lo <= err_hi, lo_first, hi)
    err = np.minimum(err_lo, err_hi)
    found = err < max_diff
    ends = best[found]
    last = np.flatnonzero(found)[-1] if found.any() else -1
    gaps = int(np.sum(~found[: last + 1])) if last >= 0 else 0
    if len(ends) < 2:
        return np.zeros(0, int), np.zeros(0, int), gaps
    return np.arange(len(ends)), ends.astype(int), gaps


def distances(p) -> np.ndarray:
    """Path length from the first pose to each (rpg's get_distance_from_start)."""
    d = np.diff(np.asarray(p, float)[:, :3], axis=0)
    return np.concatenate(([0.0], np.cumsum(np.sqrt(np.sum(d * d, axis=1)))))


def kitti_distances(p: np.ndarray) -> np.ndarray:
    """The devkit's trajectoryDistances: steps in double, accumulated into single precision."""
    steps = np.linalg.norm(np.diff(np.asarray(p, float), axis=0), axis=1)
    out = np.zeros(len(p), np.float32)
    acc = np.float32(0.0)
    for k, s in enumerate(steps.tolist(), start=1):
        acc = np.float32(float(acc) + s)
        out[k] = acc
    return out


def kitti_pairs(D32: np.ndarray, length: float):
    """(i, j): devkit's starts every 10th pose and lastFrameFromSegmentLength (first D > D[i] + L, in float)."""
    i = np.arange(0, len(D32), KITTI_STEP)
    thr = (D32[i] + np.float32(length)).astype(np.float32)
    j = np.searchsorted(D32, thr, side="right")
    keep = j < len(D32)
    return i[keep], j[keep]


def _euler_zyx(R: np.ndarray):
    """(yaw, pitch, roll) as transformations.euler_from_matrix(R, 'rzyx'), degenerate branch included."""
    cy = np.hypot(R[:, 0, 0], R[:, 1, 0])
    ok = cy > 4.0 * np.finfo(float).eps
    yaw = np.where(ok, np.arctan2(R[:, 1, 0], R[:, 0, 0]), 0.0)
    pitch = np.arctan2(-R[:, 2, 0], cy)
    roll = np.where(ok, np.arctan2(R[:, 2, 1], R[:, 2, 2]), np.arctan2(-R[:, 1, 2], R[:, 1, 1]))
    return yaw, pitch, roll


def errors(*, p_ref, q_ref, p_est, q_est, i, j, length: float, scale: float = 1.0) -> dict:
    """The six relative errors of the pairs (i, j) (module docstring), each an array."""
    Rg, Re = quat.to_matrix(q_ref), quat.to_matrix(q_est)
    Rg_i, Rg_j, Re_i, Re_j = Rg[i], Rg[j], Re[i], Re[j]
    tg = np.einsum("nki,nk->ni", Rg_i, p_ref[j] - p_ref[i])  # R_i^T (p_j - p_i)
    te = scale * np.einsum("nki,nk->ni", Re_i, p_est[j] - p_est[i])
    Rg_ij = np.einsum("nki,nkl->nil", Rg_i, Rg_j)
    Re_ij = np.einsum("nki,nkl->nil", Re_i, Re_j)
    R_err = np.einsum("nki,nkl->nil", Rg_ij, Re_ij)  # (T_g,ij^-1 T_e,ij) rotation
    t_err = np.einsum("nki,nk->ni", Rg_ij, te - tg)
    R_w = np.einsum("nij,njk,nlk->nil", Re_j, R_err, Re_j)
    t_w = np.einsum("nij,nj->ni", Re_j, t_err)
    trans = np.sqrt(np.sum(t_w**2, axis=1))
    tr = np.trace(R_w, axis1=1, axis2=2)
    rot = np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))
    yaw, pitch, roll = _euler_zyx(R_w)
    return {
        "trans": trans,
        "trans_perc": trans / length * 100.0,
        "rot": rot,
        "rot_deg_per_m": rot / length,
        "yaw": np.degrees(np.abs(yaw)),
        "gravity": np.degrees(np.sqrt(pitch**2 + roll**2)),
    }


def relative_errors(
    *, ref_path_length: float, p_ref, q_ref, p_est, q_est, items, method: str = "rpg", scale: float = 1.0
) -> dict:
    """``{label: {"length": m, "pairs": (i, j), "gaps": k, <error>: array}}`` for each length item."""
    if method not in METHODS:
        raise ReplayError(f"--lengths-method {method!r}: expected one of {', '.join(METHODS)}")
    if q_ref is None or q_est is None:
        raise ReplayError(
            "--lengths needs orientations in the reference and the estimate (relative rotation "
            "errors): a positions-only trajectory cannot be scored over lengths"
        )
    p_ref, p_est = np.asarray(p_ref, float), np.asarray(p_est, float)
    out = {}
    D = distances(p_ref)
    D32 = kitti_distances(p_ref) if method == "kitti" else None
    for name, m in resolve(items, ref_path_length):
        if method == "rpg":
            i, j, gaps = rpg_pairs(D, m, RPG_MAX_DIFF * m)
        else:
            (i, j), gaps = kitti_pairs(D32, m), 0
        entry = {"length": m, "pairs": (i, j), "gaps": gaps}
        entry.update(errors(p_ref=p_ref, q_ref=q_ref, p_est=p_est, q_est=q_est, i=i, j=j, length=m, scale=scale))
        out[name] = entry
    return out


def statistics(e) -> dict:
    """rpg's compute_statistics: rmse, mean, median, std, min, max, num_samples (NaN and 0 when empty)."""
    e = np.asarray(e, float)
    if not len(e):
        return {**{k: float("nan") for k in ("rmse", "mean", "median", "std", "min", "max")}, "num_samples": 0}
    return {
        "rmse": float(np.sqrt(np.dot(e, e) / len(e))),
        "mean": float(np.mean(e)),
        "median": float(np.median(e)),
        "std": float(np.std(e)),
        "min": float(np.min(e)),
        "max": float(np.max(e)),
        "num_samples": len(e),
    }


def table(result: dict, method: str) -> str:
    """The printed block: per length, one line per error with its statistics."""
    stats = ("rmse", "mean", "median", "std", "min", "max")
    source = "rpg_trajectory_evaluation" if method == "rpg" else "KITTI devkit"
    out = [f"Relative errors over lengths ({method}: {source} sub-trajectories)"]
    for name, entry in result.items():
        i, _ = entry["pairs"]
        out.append(
            f"\nlength {name} = {entry['length']:g} m: {len(i)} sub-trajectories"
            + (
                f" ({entry['gaps']} starts without an end within 20 % of the length: ends paired with "
                "shifted starts, as rpg does)"
                if entry["gaps"]
                else ""
            )
        )
        out.append(f"{'error':>20}" + "".join(f"{k:>13}" for k in stats))
        for err in ERRORS:
            st = statistics(entry[err])
            out.append(f"{err + ' (' + UNITS[err] + ')':>20}" + "".join(f"{st[k]:>13.6f}" for k in stats))
    return "\n".join(out) + "\n"


def rows(base: dict, result: dict, method: str) -> list:
    """One CSV row per length: ``base`` and ``length``, ``length_m``, ``lengths_method``, ``rel_<error>_<stat>``."""
    out = []
    for name, entry in result.items():
        row = dict(base, length=name, length_m=entry["length"], lengths_method=method)
        for err in ERRORS:
            row.update({f"rel_{err}_{k}": v for k, v in statistics(entry[err]).items()})
        out.append(row)
    return out
