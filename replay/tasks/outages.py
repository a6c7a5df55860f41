"""The outage / resurfacing protocol of the ``fusion`` task (``--task-param score=outages``).

A recording whose reference is the vehicle's own solution or a fed sensor cannot rank filters
on it: the reference shares a source with an input. What it can give is the error at the end of
an outage, against a fix no filter has seen. An **outage** is

* a gap the recording has itself: two successive fixes more than ``outage_gap`` s apart (an AUV's
  dive: its GPS has no fix under water), and
* a withheld window (``outage`` > 0): in each period of ``outage_every`` s from the first fix, the
  fixes of its last ``outage`` s are withheld from every filter.

The first fix after an outage (the *resurfacing fix*) is withheld too; it is the reference
there, and only there: each filter is scored at the resurfacing fixes, one sample per event.
The error at the end of each outage is the headline (:mod:`replay.scoring.outages` tabulates it
per event, with its interval across events). The ``measurements`` row then holds the last fed
fix through the outage: the hold-last-fix baseline, scored at the same fixes.
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import ReplayError
from replay.util.params import Param

PARAMS = (
    Param(
        "score",
        str,
        "reference",
        "what the rows are scored against: the recording's position reference, or the first fix after "
        "each outage, withheld from every filter (replay.tasks.outages)",
        choices=("reference", "outages"),
    ),
    Param(
        "outage_gap",
        float,
        10.0,
        "score=outages: a gap between fixes longer than this is an outage (a dive)",
        unit="s",
        low=0,
        low_open=True,
    ),
    Param(
        "outage",
        float,
        0.0,
        "score=outages: also withhold the fixes of the last `outage` s of every "
        "outage_every s (0: the recording's own gaps only)",
        unit="s",
        low=0,
    ),
    Param(
        "outage_every", float, 60.0, "score=outages: the period of the withheld windows", unit="s", low=0, low_open=True
    ),
)


def events(t, fix, gap: float, length: float = 0.0, every: float = 0.0):
    """``(fed, ends, starts)``: the fixes still fed (bool per step), the steps of the resurfacing
    fixes (int array) and the time of the last fed fix before each (the outage's start), for
    the fixes ``fix`` (bool per step) at times ``t`` (module docstring)."""
    t = np.asarray(t, float)
    fed = np.asarray(fix, bool).copy()
    if length > 0:
        if every <= length:
            raise ReplayError(
                f"task fusion: outage_every = {every:g} s must exceed outage = {length:g} s (a window of fed "
                "fixes must come before each outage)"
            )
        idx = np.flatnonzero(fed)
        if len(idx):
            phase = (t[idx] - t[idx[0]]) % every
            fed[idx[phase >= every - length]] = False  # the last `length` s of every period
    ends = []
    idx = np.flatnonzero(fed)
    withheld = np.asarray(fix, bool) & ~fed
    for a, b in zip(idx[:-1], idx[1:]):
        if t[b] - t[a] > gap or withheld[a + 1 : b].any():
            ends.append(b)  # the first fix after the outage
    ends = np.array(ends, dtype=np.int64)
    fed[ends] = False  # the resurfacing fix is the reference there, never a filter's input
    left = np.flatnonzero(fed)
    before = np.searchsorted(left, ends) - 1  # the last fix fed before each end (none: the recording's start)
    starts = np.where(before >= 0, t[left[np.maximum(before, 0)]] if len(left) else t[0], t[0])
    return fed, ends, np.asarray(starts, float)


def withhold(task, valid, vals, t, where):
    """The fixes of a gps position input (``valid``, ``vals``) under the protocol: the fixes still
    fed, and the record ``(vals, ends, starts)`` the reference is made of (:func:`reference`)."""
    fed, ends, starts = events(t, valid, task.outage_gap, task.outage, task.outage_every)
    if not len(ends):
        raise ReplayError(
            f"{where}: task fusion: score=outages: no outage in the recording (no gap of more than outage_gap = "
            f"{task.outage_gap:g} s between fixes); withhold windows with --task-param outage=SECONDS"
        )
    return fed, (vals, ends, starts)


def reference(outage, d: int, n: int, t, where):
    """``(truth (n, d), valid (n,), params)``: the resurfacing fixes as the reference, valid only there."""
    vals, ends, starts = outage
    if vals.shape[1] < d:
        raise ReplayError(f"{where}: task fusion: score=outages: the fixes have {vals.shape[1]} axes, the state {d}")
    truth = np.full((n, d), np.nan)
    truth[ends] = vals[ends, :d]
    valid = np.zeros(n, bool)
    valid[ends] = True
    spans = [[round(float(a), 6), round(float(t[e]), 6)] for a, e in zip(starts, ends)]
    return truth, valid, {"outage_events": len(ends), "outages": spans}
