"""The reference of a lake-trial log on the sensor times, without inventing samples (:func:`align`)."""

from __future__ import annotations

import numpy as np

from replay.util.angles import wrap

MAX_GAP = 0.5  # s: longest reference gap bridged by interpolation


def align(
    t: np.ndarray, tr: np.ndarray, vr: np.ndarray, max_gap: float = MAX_GAP, angle: bool = False, tol: float = 1e-6
):
    """Reference samples (tr, vr) on times ``t`` without inventing samples.

    Returns ``(values, valid, counts)``: a time within ``tol`` of a reference
    sample takes its value (``exact``); a time between two reference samples at
    most ``max_gap`` apart is linearly interpolated (``interpolated``; angles by
    their wrapped difference); a time inside a longer gap (``in_gaps``, with
    ``gaps`` the number of such gaps that hold sensor samples) or outside
    [tr[0], tr[-1]] (``outside``) is masked.
    """
    out = np.full(len(t), np.nan)
    n = len(tr)
    counts = {"exact": 0, "interpolated": 0, "in_gaps": 0, "gaps": 0, "outside": 0}
    if n == 0:
        counts["outside"] = len(t)
        return out, np.zeros(len(t), bool), counts
    j = np.searchsorted(tr, t)  # tr[j-1] < t <= tr[j]
    hi = np.clip(j, 0, n - 1)
    lo = np.clip(j - 1, 0, n - 1)
    exact_hi = np.abs(tr[hi] - t) <= tol
    exact_lo = np.abs(tr[lo] - t) <= tol
    exact = exact_hi | exact_lo
    out[exact_hi] = vr[hi[exact_hi]]
    out[exact_lo & ~exact_hi] = vr[lo[exact_lo & ~exact_hi]]
    inside = ~exact & (j > 0) & (j < n)
    span = tr[hi] - tr[lo]
    interp = inside & (span <= max_gap)
    gap = inside & (span > max_gap)
    frac = (t[interp] - tr[lo[interp]]) / span[interp]
    d = vr[hi[interp]] - vr[lo[interp]]
    out[interp] = vr[lo[interp]] + (wrap(d) if angle else d) * frac
    counts.update(
        exact=int(exact.sum()),
        interpolated=int(interp.sum()),
        in_gaps=int(gap.sum()),
        gaps=int(len(np.unique(j[gap]))),
        outside=int((~exact & ~inside).sum()),
    )
    return out, exact | interp, counts
