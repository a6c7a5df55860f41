"""Time association of an estimate with its reference, as evo's ``associate_trajectories``.

Each pose of the trajectory with fewer poses (the estimate when both have as many) is
matched with the nearest-in-time pose of the other, after adding ``t_offset`` to the
estimate's stamps, when they are at most ``t_max_diff`` apart (a tie goes to the earlier
pose; a pose of the longer trajectory may be matched twice). Unmatched poses are left out.
This reproduces evo's ``sync.matching_time_indices`` index for index (``nearest_time``).

Refused in one line naming both sources: time spans that do not overlap (even within
``t_max_diff``), and fewer than :data:`MIN_MATCHES` matched poses.
"""

from __future__ import annotations

import numpy as np

from replay.trajectory.base import Trajectory
from replay.util.errors import ReplayError

MIN_MATCHES = 3
T_MAX_DIFF = 0.01  # s, evo's default


def matching_indices(short: np.ndarray, long: np.ndarray, max_diff: float):
    """Indices (i_short, i_long) of nearest matches within ``max_diff`` (``long`` sorted)."""
    s = np.asarray(short, float)
    L = np.asarray(long, float)
    inside = (s >= L[0] - max_diff) & (s <= L[-1] + max_diff)
    k = np.minimum(np.searchsorted(L, s, side="right"), len(L) - 1)
    ub = L[k] - s
    lb = np.where(k > 0, s - L[np.maximum(k - 1, 0)], np.inf)
    take_ub = (ub <= max_diff) & (ub < lb)
    take_lb = ~take_ub & (lb <= max_diff) & (lb <= ub)
    ok = inside & (take_ub | take_lb)
    return np.flatnonzero(ok), np.where(take_ub, k, k - 1)[ok]


def associate_times(t_ref, t_est, t_max_diff: float = 0.01, t_offset: float = 0.0):
    """Pairs ``(i_ref, i_est)`` of strictly increasing stamps as evo's ``sync.associate_trajectories``
    (``t_offset`` added to the estimate's; the shorter drives, nearest within ``t_max_diff``, the
    earlier on a tie: :func:`matching_indices`, shared with ``replay score``)."""
    a, b = np.asarray(t_ref, float), np.asarray(t_est, float)
    if not len(a) or not len(b):
        return np.zeros(0, int), np.zeros(0, int)
    if len(b) > len(a):
        return matching_indices(a, b + t_offset, t_max_diff)
    j, i = matching_indices(b, a - t_offset, t_max_diff)
    return i, j


def associate(
    ref: Trajectory,
    est: Trajectory,
    *,
    t_max_diff: float = T_MAX_DIFF,
    t_offset: float = 0.0,
    min_matches: int = MIN_MATCHES,
):
    """(ref indices, est indices) of the matched poses (module docstring)."""
    if not t_max_diff >= 0:
        raise ReplayError(f"t_max_diff {t_max_diff}: expected a time difference >= 0 s")
    names = f"{est.source or est.name} against {ref.source or ref.name}"
    lo, hi = est.t[0] + t_offset, est.t[-1] + t_offset
    if hi < ref.t[0] - t_max_diff or lo > ref.t[-1] + t_max_diff:
        raise ReplayError(
            f"{names}: the time spans do not overlap (estimate {lo:.3f} .. {hi:.3f} s"
            f"{f' with t_offset {t_offset:g} s' if t_offset else ''}, reference {ref.t[0]:.3f} .. "
            f"{ref.t[-1]:.3f} s)"
        )
    if len(est) > len(ref):
        i_ref, i_est = matching_indices(ref.t, est.t + t_offset, t_max_diff)
    else:
        i_est, i_ref = matching_indices(est.t, ref.t - t_offset, t_max_diff)
    if len(i_ref) < min_matches:
        raise ReplayError(
            f"{names}: {len(i_ref)} pose{'s' if len(i_ref) != 1 else ''} matched within "
            f"t_max_diff {t_max_diff:g} s{f' (t_offset {t_offset:g} s)' if t_offset else ''}; at least "
            f"{min_matches} are needed (stamps in different clocks? try --t-offset or --t-max-diff)"
        )
    return i_ref, i_est
