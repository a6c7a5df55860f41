"""Validity of the reference position: jumps of the navigation solution and GPS contradictions."""

from __future__ import annotations

import numpy as np

NOMINAL_STEP = 0.1  # s: the logs are about 10 Hz; jump_threshold is per such step


def _reach(dt, jump_threshold, max_speed):
    """Largest plausible displacement (m) over ``dt`` seconds."""
    return np.minimum(jump_threshold * dt / NOMINAL_STEP, max_speed * dt + jump_threshold)


def find_jumps(t, p, jump_threshold=5.0, max_speed=10.0):
    """Indices of the samples that follow a jump: a step > jump_threshold per 0.1 s."""
    step = np.hypot(*np.diff(p, axis=0).T)
    return np.flatnonzero(step > _reach(np.diff(t), jump_threshold, max_speed)) + 1


def mask_jumps(t, p, jump_threshold=5.0, max_speed=10.0, block=10):
    """Keep-mask for a track ``p`` (n, 2) in metres (all finite).

    A *jump* is a step between consecutive samples longer than
    ``jump_threshold`` per 0.1 s (scaled by the actual step). Two samples are
    *compatible* when their distance is at most ``min(jump_threshold * dt /
    0.1, max_speed * dt + jump_threshold)``: never a jump, and across a masked
    gap no faster than ``max_speed`` plus one jump_threshold of slack. The
    kept samples are the largest set in which each kept sample is compatible
    with the next kept one, found by dynamic programming over blocks (the
    jump-free runs cut into pieces of ``block`` samples), then grown back
    sample by sample at the edges of each masked stretch. A spike or a
    displaced stretch that comes back (out and back) is masked as a whole; at
    a step that persists, the samples next to the step are masked until the
    rest is reachable at ``max_speed``. Nothing else is masked.

    Linear time (:func:`_best_chain`): a block that continues the best chain so
    far is decided without looking further back.
    """
    t = np.asarray(t, float)
    p = np.asarray(p, float)
    n = len(t)
    jumps = find_jumps(t, p, jump_threshold, max_speed) if n > 1 else np.zeros(0, int)
    if not len(jumps):
        return np.ones(n, bool)
    starts = np.union1d(np.arange(0, n, block), jumps)
    ends = np.r_[starts[1:], n] - 1
    prev, best = _best_chain(t, p, starts, ends, np.isin(starts, jumps), jump_threshold, max_speed)
    keep = np.zeros(n, bool)
    k = len(starts) - 1 - int(np.argmax(best[::-1]))
    while k >= 0:
        keep[starts[k] : ends[k] + 1] = True
        k = prev[k]
    _regrow(t, p, keep, jump_threshold, max_speed)
    return keep


def _best_chain(t, p, starts, ends, at_jump, jump_threshold, max_speed, chunk=64, coarse=256):
    """The dynamic programme of :func:`mask_jumps`: for each block k, ``best[k]`` the most
    samples in a compatible chain of blocks ending with k, and ``prev[k]`` the block before
    it (the latest among equals; -1 for none).

    ``best[k]`` is the best over the earlier blocks j whose last sample is compatible with
    k's first. Three shortcuts give the same answer as trying every j: (1) when block k-1
    holds the largest ``best`` so far and k does not start at a jump (consecutive samples
    without a jump are compatible), j = k-1 is the answer, and the chain stays on top
    until the next jump: such runs of blocks are filled at once; (2) otherwise the earlier
    blocks are tried backwards in chunks, and the search stops where the running maximum
    of ``best`` can no longer beat what was found (no earlier block can win); (3) beyond the
    last few ``coarse`` groups of blocks, a group is tried only when its best can beat what
    was found and the box around its blocks' last samples is within reach (a track that
    moved far away and stays there does not make every later block look at every earlier one).
    """
    m = len(starts)
    size = (ends - starts + 1).astype(float)
    best = np.zeros(m)
    prev = np.full(m, -1)
    top = np.zeros(m)  # running maximum of best[:k + 1]
    group_best = np.full(-(-m // coarse), -1.0)  # max of best over each coarse group so far
    first = np.arange(0, m, coarse)
    e = p[ends]
    box = [f.reduceat(e[:, i], first) for i in (0, 1) for f in (np.minimum, np.maximum)]
    after = np.flatnonzero(at_jump)  # blocks that start at a jump: never continue k-1 as such

    def scan(k, lo, hi, found, v):
        """(found, v) updated with the latest best compatible block among lo .. hi-1."""
        j = np.arange(lo, hi)
        d = np.hypot(*(e[j] - p[starts[k]]).T)
        ok = d <= _reach(t[starts[k]] - t[ends[j]], jump_threshold, max_speed)
        if ok.any():
            cand = np.where(ok, best[j], -1.0)
            i = len(j) - 1 - int(np.argmax(cand[::-1]))
            if cand[i] > v:
                return lo + i, float(cand[i])
        return found, v

    k = 0
    while k < m:
        if k and best[k - 1] == top[k - 1] and not at_jump[k]:
            # (1) the chain on top continues up to the next block that starts at a jump
            stop = after[np.searchsorted(after, k)] if after[-1] >= k else m
            run = np.arange(k, stop)
            prev[run] = run - 1
            best[run] = best[k - 1] + np.cumsum(size[run])
            top[run] = best[run]
            np.maximum.at(group_best, run // coarse, best[run])
            k = stop
            continue
        found, v = -1, -1.0
        near = max(0, (k // coarse - 4) * coarse)  # (2) elementwise down to here, (3) below
        hi, width = k, chunk
        while hi > near and top[hi - 1] > v:
            lo = max(near, hi - width)
            found, v = scan(k, lo, hi, found, v)
            hi, width = lo, width * 2
        if hi == near and near > 0 and top[near - 1] > v:
            g = near // coarse
            x, y = p[starts[k]]
            dx = np.maximum(np.maximum(box[0][:g] - x, x - box[1][:g]), 0.0)
            dy = np.maximum(np.maximum(box[2][:g] - y, y - box[3][:g]), 0.0)
            reach = _reach(t[starts[k]] - t[ends[first[:g]]], jump_threshold, max_speed)
            maybe = (group_best[:g] > v) & (np.hypot(dx, dy) <= reach * (1 + 1e-9) + 1e-9)
            for c in np.flatnonzero(maybe)[::-1]:
                if top[(c + 1) * coarse - 1] <= v:
                    break
                if group_best[c] > v:
                    found, v = scan(k, c * coarse, (c + 1) * coarse, found, v)
        if found >= 0:
            prev[k] = found
            best[k] = best[found]
        best[k] += size[k]
        top[k] = max(top[k - 1], best[k]) if k else best[k]
        group_best[k // coarse] = max(group_best[k // coarse], best[k])
        k += 1
    return prev, best


def _regrow(t, p, keep, jump_threshold, max_speed):
    """Unmask samples at the edges of masked stretches while they stay compatible."""

    def ok(i, j):
        if i is None or j is None:
            return True
        return np.hypot(*(p[j] - p[i])) <= _reach(t[j] - t[i], jump_threshold, max_speed)

    n = len(t)
    for a, b in _runs(~keep):
        lo = a - 1 if a > 0 else None
        hi = b + 1 if b < n - 1 else None
        while b >= a and ok(b, hi) and ok(lo, b):
            keep[b] = True
            hi, b = b, b - 1
        while a <= b and ok(lo, a) and ok(a, hi):
            keep[a] = True
            lo, a = a, a + 1


def _runs(mask):
    """(first, last) index pairs of the runs of True in ``mask``."""
    idx = np.flatnonzero(mask)
    if not len(idx):
        return []
    cut = np.flatnonzero(np.diff(idx) > 1)
    return list(zip(np.r_[idx[0], idx[cut + 1]], np.r_[idx[cut], idx[-1]]))


def gps_contradiction(t, p, fixes, fix_p, after_jump, tolerance=15.0, window=1.0):
    """Reference samples that fresh GPS fixes contradict, and each fix's distance.

    ``fixes`` are the sample indices of fresh, valid fixes at ``fix_p``; ``p``
    is the reference (NaN where unknown); ``after_jump`` marks the samples
    that follow a jump of the reference. A fix contradicts the reference when
    they are more than ``tolerance`` apart at the fix. Masked: the samples
    whose nearest fix (within ``window`` s) contradicts the reference, and all
    samples between two consecutive contradicting fixes when the reference
    makes no jump between them (its offset cannot have gone away).
    """
    n = len(t)
    out = np.zeros(n, bool)
    if not len(fixes):
        return out, np.zeros(0)
    dist = np.hypot(*(p[fixes] - fix_p).T)
    bad = dist > tolerance
    tf = t[fixes]
    k = np.clip(np.searchsorted(tf, t), 1, max(len(tf) - 1, 1))
    left = np.minimum(k - 1, len(tf) - 1)
    right = np.minimum(k, len(tf) - 1)
    near = np.where(np.abs(t - tf[left]) <= np.abs(tf[right] - t), left, right)
    out |= (np.abs(t - tf[near]) <= window) & bad[near]
    seg = np.cumsum(after_jump)
    pair = bad[:-1] & bad[1:] & (seg[fixes[:-1]] == seg[fixes[1:]])
    mark = np.zeros(n + 1, int)
    np.add.at(mark, fixes[:-1][pair], 1)
    np.add.at(mark, fixes[1:][pair] + 1, -1)
    out |= np.cumsum(mark)[:n] > 0
    return out, dist


def _reference_mask(t, utm, geo_ok, gps, lines, report, meta, jump_threshold, max_speed, gps_tolerance):
    """Validity of the reference: plausible lat/lon, not contradicted by GPS, no jumps.

    Two stages. First (36-column files) the samples that fresh GPS fixes
    contradict (:func:`gps_contradiction`): this decides which side of a
    persistent step is displaced whenever the vehicle is at the surface.
    Then :func:`mask_jumps` on what is left removes spikes, displaced
    stretches and the samples next to the remaining steps.
    """
    n = len(t)
    idx = np.flatnonzero(geo_ok)
    jumps = idx[find_jumps(t[idx], utm[idx], jump_threshold, max_speed)]
    steps = np.hypot(*(utm[jumps] - utm[idx[np.searchsorted(idx, jumps) - 1]]).T)
    valid = geo_ok.copy()
    contra = np.zeros(n, bool)
    gps_check = gps is not None and gps_tolerance is not None
    if gps_check:
        fixes = np.flatnonzero(gps["valid"])
        after_jump = np.zeros(n, bool)
        after_jump[jumps] = True
        contra, dist = gps_contradiction(t, utm, fixes, gps["utm"][fixes], after_jump, gps_tolerance)
        contra &= geo_ok
        valid &= ~contra
        far = dist > gps_tolerance
        gps["info"].update(
            median_distance_to_reference_m=float(np.nanmedian(dist)), fixes_contradicting_reference=int(far.sum())
        )
        worst = int(np.nanargmax(np.nan_to_num(dist, nan=-1.0)))
        report.add(
            "info",
            "gps_position",
            len(fixes),
            f"fresh fixes vs navigation solution: median {np.nanmedian(dist):.1f} m, "
            f"{int(far.sum())} fixes > {gps_tolerance:g} m (largest {dist[worst]:.1f} m "
            f"at line {lines[fixes[worst]]})",
        )
        if contra.any():
            report.add(
                "masked",
                "position",
                int(contra.sum()),
                f"contradicted by fresh GPS fixes: {int(far.sum())} fixes > {gps_tolerance:g} m "
                f"from the navigation solution; samples within 1 s of them, and between "
                f"consecutive ones without a jump, masked ({len(_runs(contra))} stretches)",
            )
    rest = np.flatnonzero(valid)
    keep = mask_jumps(t[rest], utm[rest], jump_threshold, max_speed)
    kinematic = np.zeros(n, bool)
    kinematic[rest[~keep]] = True
    valid &= ~kinematic
    masked = contra | kinematic
    meta["jumps"] = {
        "events": len(jumps),
        "largest_m": float(steps.max()) if len(steps) else 0.0,
        "masked": int(masked.sum()),
        "masked_gps": int(contra.sum()),
        "masked_kinematic": int(kinematic.sum()),
        "stretches": len(_runs(masked)),
        "steps": [{"line": int(lines[i]), "t": float(t[i]), "step_m": float(s)} for i, s in zip(jumps, steps)],
        "method": (f"masked where fresh GPS fixes contradict it by > {gps_tolerance:g} m, then " if gps_check else "")
        + f"the largest set of samples with no step > {jump_threshold:g} m per 0.1 s and "
        f"no motion > {max_speed:g} m/s across masked stretches",
    }
    if len(jumps):
        i = int(np.argmax(steps))
        report.add(
            "masked",
            "position",
            int(kinematic.sum()),
            f"{len(jumps)} jumps > {jump_threshold:g} m per 0.1 s in the navigation solution "
            f"(largest {steps[i]:.1f} m at line {lines[jumps[i]]}); {int(kinematic.sum())} "
            f"displaced samples in {len(_runs(kinematic))} stretches masked so that no "
            f"kept step is a jump and no masked gap is crossed faster than {max_speed:g} m/s",
        )
    return valid
