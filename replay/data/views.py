"""Views of a dataset: a time window, a segment and a sampling rate, applied to any frame.

Views are dataset parameters accepted by every dataset (simulated, registered,
plain files, bags): :func:`replay.data.registry.check_params` checks them beside the
generator's or adapter's own parameters and :func:`replay.data.registry.load_frame`
applies them to the frame the adapter or generator made, before ``first``. So
they are part of ``dataset_params``: of the configuration hash, the manifest,
``replay rerun`` and campaign units, with nothing else to do.

* ``window = "START:END"``: the samples with ``START <= t < END``, in seconds
  from the first sample (either bound may be empty: ``"60:"``, ``":120.5"``);
  ``"#I:J"``: the samples of index ``I <= i < J`` (Python slice, no negatives).
* ``segment = "A:B"``: fractions of the duration, ``0 <= A < B <= 1``: the
  samples with ``A·D <= t < B·D`` (``B = 1`` keeps the last sample), so
  ``0:0.6`` and ``0.6:1`` share no sample. With a window, it is a share of the
  window.
* ``rate = HZ``: a regular grid ``t_i = i / rate`` over the (cut) frame. Each
  channel, sensor and reference alike, takes at each grid point its *valid*
  sample nearest in time within half a period (in ``[t_i - T/2, t_i + T/2)``;
  the earlier on a tie), so a sample is taken at most once and no value is
  averaged or interpolated (angles stay samples). A grid point with no valid
  sample in its half-period is masked (``valid = False``, value NaN) for that
  channel. The report counts per channel the valid samples not taken
  (``dropped``), the grid points masked and the largest time shift.

Order: window, then segment, then rate. The dataset parameter ``fault`` (injected sensor faults,
:mod:`replay.data.faults`) is checked here with the views, and applied after them and ``first``,
with the run's fault stream (:mod:`replay.data.fault_apply`). The cut frame's times are re-based by
the offset of its first sample from the original first sample, so it starts
where the original started (``t = 0`` for a recording: the frame convention);
the grid starts there too. ``meta["view"]`` keeps the offset (``offset_s``), the
original sample range and the grid; ``epoch`` moves with the offset. Recorded
estimates keep their own stamps (re-based alike, cut to the kept span); the frame's maneuvers
are re-based alike (those wholly outside the kept span are left out).

A simulation whose task starts from its simulated first state and steps at
its generation step (``Frame.simulation``'s initial state and ``dt``: ``sim/ungm``,
``sim/auv-sonar``, ...) takes only views that keep its first sample and its
step (a window ``:END``, a segment ``0:B``); the others are refused in one line
(the task's model would not describe the frame). Its training and test data
differ by seed (:mod:`replay.data.splits`).
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np

from replay.util.errors import ReplayError
from replay.util.params import Param
from replay.frame import Report, Channel
from replay.data import faults
from replay.data.smoothed_reference import replace

VIEW_PARAMS = (
    Param(
        "rate",
        float,
        None,
        "resample onto a regular grid at this rate: per channel the valid sample nearest each "
        "grid point within half a period, else masked (no sample invented or averaged)",
        unit="Hz",
        low=0.0,
        low_open=True,
        optional=True,
    ),
    Param(
        "window",
        str,
        None,
        "keep START <= t < END, seconds from the first sample (either bound may be empty, "
        "e.g. 60:, :120.5), or #I:J sample indices; times shifted back by the start",
        optional=True,
    ),
    Param(
        "segment",
        str,
        None,
        "keep the share A:B of the duration (0 <= A < B <= 1, e.g. 0:0.6, 0.6:1); applied after window",
        optional=True,
    ),
    Param(
        "reference",
        str,
        None,
        "a track written by replay export --tum (a smoothed row) as the position reference, its "
        "provenance printed and recorded (replay.data.smoothed_reference); applied after the other views",
        optional=True,
    ),
)
NAMES = tuple(p.name for p in VIEW_PARAMS) + ("fault",)  # and the injected faults (replay.data.faults)
_NUM = r"\s*(\d+(?:\.\d*)?(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?)?\s*"
_WINDOW_HELP = "START:END in seconds from the first sample (e.g. 60:120, 60:, :120.5) or #I:J sample indices"


def split(params: dict) -> tuple[dict, dict]:
    """(the view parameters of ``params``, the others)."""
    return ({k: v for k, v in params.items() if k in NAMES}, {k: v for k, v in params.items() if k not in NAMES})


def check(views: dict, owner: str = "") -> dict:
    """The view parameters checked, canonical (a bound as its shortest text), ``None`` ones left out."""
    where = f"{owner}: " if owner else ""
    out = {}
    for p in VIEW_PARAMS:
        value = p.check(views.get(p.name), owner)
        if value is None:
            continue
        if p.name == "window":
            value = _fmt_window(*_parse_window(value, where))
        elif p.name == "segment":
            value = _fmt_bounds(*_parse_segment(value, where))
        out[p.name] = value
    if views.get("fault") is not None:
        out["fault"] = faults.check(views["fault"], owner)
    return out


def _parse_window(text: str, where: str) -> tuple[bool, float | None, float | None]:
    index = text.strip().startswith("#")
    m = re.fullmatch(_NUM + ":" + _NUM, text.strip()[1:] if index else text)
    if m is None:
        raise ReplayError(f"{where}window must be {_WINDOW_HELP} (got {text!r})")
    lo, hi = (None if g is None else float(g) for g in m.groups())
    if index and any(b is not None and b != int(b) for b in (lo, hi)):
        raise ReplayError(f"{where}window {text!r}: sample indices after '#' must be whole numbers")
    if any(b is not None and not math.isfinite(b) for b in (lo, hi)):
        raise ReplayError(f"{where}window {text!r}: the bounds must be finite")
    if lo is None and hi is None:
        raise ReplayError(f"{where}window {text!r} keeps everything: give a bound, or no window")
    if lo is not None and hi is not None and hi <= lo:
        raise ReplayError(f"{where}window {text!r}: the end must be after the start")
    return index, lo, hi


def _parse_segment(text: str, where: str) -> tuple[float, float]:
    m = re.fullmatch(_NUM + ":" + _NUM, text)
    lo, hi = (None, None) if m is None else (None if g is None else float(g) for g in m.groups())
    lo, hi = 0.0 if lo is None else lo, 1.0 if hi is None else hi
    if m is None or not 0 <= lo < hi <= 1:
        raise ReplayError(
            f"{where}segment must be A:B with 0 <= A < B <= 1, shares of the recording's duration "
            f"(e.g. 0:0.6, 0.6:1) (got {text!r})"
        )
    if (lo, hi) == (0, 1):
        raise ReplayError(f"{where}segment {text!r} keeps everything: give a share, or no segment")
    return lo, hi


def _num(x: float | None) -> str:
    return "" if x is None else (str(int(x)) if x == int(x) else repr(float(x)))


def _fmt_bounds(lo, hi) -> str:
    return f"{_num(lo)}:{_num(hi)}"


def _fmt_window(index: bool, lo, hi) -> str:
    return ("#" if index else "") + _fmt_bounds(lo, hi)


# ---------------------------------------------------------------- applying


def apply(frame, views: dict, source: str = "dataset"):
    """``frame`` cut and resampled by ``views`` (checked by :func:`check`); ``frame`` itself when
    there are none. A new frame: the input frame (perhaps cached) and its report are not changed."""
    views = {k: v for k, v in check(views, source).items() if k != "fault"}  # faults: fault_apply, per run
    if "reference" in views:  # a smoothed track as the reference: on the frame the other views made
        reference = views.pop("reference")
        return replace(apply(frame, views, source), reference, source)
    if not views:
        return frame
    n0, t = len(frame.t), frame.t
    if n0 < 2:
        raise ReplayError(f"{source}: a view needs 2 samples at least; the recording has {n0}")
    span = float(t[-1] - t[0])
    keep = np.ones(n0, bool)
    if "window" in views:
        index, lo, hi = _parse_window(views["window"], "")
        pos = np.arange(n0) if index else t - t[0]
        keep &= (pos >= (lo if lo is not None else -np.inf)) & (pos < (hi if hi is not None else np.inf))
        _need(keep, f"the window {views['window']}", frame, source, span)
    if "segment" in views:
        lo, hi = _parse_segment(views["segment"], "")
        tk = t[keep]
        d, t0 = float(tk[-1] - tk[0]), tk[0]
        inside = (t >= t0 + lo * d) & ((t < t0 + hi * d) | (hi == 1))
        keep &= inside
        _need(keep, f"the segment {views['segment']}", frame, source, span)
    idx = np.flatnonzero(keep)
    offset = float(t[idx[0]] - t[0])
    _check_simulation(frame, views, offset, source)
    view = dict(views, offset_s=offset, samples=[int(idx[0]), int(idx[-1]) + 1], of=n0)
    out = _rebuild(
        frame,
        t[idx] - offset,
        {k: c.take(idx) for k, c in frame.channels.items()},
        {k: c.take(idx) for k, c in frame.reference.items()},
        offset,
        view,
    )
    if "window" in views or "segment" in views:
        out.report.add(
            "dropped",
            "samples",
            n0 - len(idx),
            f"outside the view {_describe(views)} "
            f"(kept samples {idx[0]}..{idx[-1]} of {n0}, times re-based by {offset:.3f} s)",
        )
    return resample(out, views["rate"]) if "rate" in views else out


def _check_simulation(frame, views, offset, source):
    """A simulation whose task starts from its simulated state at the first sample and steps at the
    generation step (``frame.simulation``: its initial state and ``dt``) cannot be cut at its start or
    resampled: its task's model would no longer describe the frame. One line instead of a wrong number."""
    if frame.simulation is None or frame.simulation.initial_state is None:
        return
    dt = frame.simulation.dt
    if offset > 0:
        why = f"{_describe(views)} starts {offset:g} s after the first sample"
    elif "rate" in views and not (isinstance(dt, (int, float)) and abs(views["rate"] * dt - 1) < 1e-12):
        why = f"rate {views['rate']:g} Hz resamples a simulation generated every {dt} s"
    else:
        return
    raise ReplayError(
        f"{source}: {why}, but its task starts from the simulated state at the first sample and "
        "steps at the generation step; simulate what you need with the generator's own parameters "
        f"(replay list datasets), cut its end with --first or a window ':END'"
    )


def _need(keep, what, frame, source, span):
    if keep.sum() < 2:
        n = int(keep.sum())
        held = "no sample" if n == 0 else "1 sample (2 at least are needed)"
        raise ReplayError(f"{source}: {what} holds {held} of the {span:g} s recording ({len(frame.t)} samples)")


def _describe(views: dict) -> str:
    return ", ".join(f"{k} {views[k]}" for k in ("window", "segment") if k in views)


def _rebuild(frame, t, channels, reference, offset, view, report=None):
    start, end = float(t[0]), float(t[-1])
    estimates = {}
    for name, e in frame.estimates.items():
        shifted = type(e)(
            e.t - offset, e.position, e.orientation, e.covariance, e.frame, e.child, e.description, dict(e.params)
        )
        keep = (shifted.t >= start - 1e-9) & (shifted.t <= end + 1e-9)
        pick = lambda a: None if a is None else a[keep]
        estimates[name] = type(e)(
            shifted.t[keep],
            shifted.position[keep],
            pick(shifted.orientation),
            pick(shifted.covariance),
            e.frame,
            e.child,
            e.description,
            dict(e.params),
        )
    maneuvers = [(a - offset, b - offset, label) for a, b, label in frame.maneuvers]
    return dataclasses.replace(
        frame,
        t=t,
        channels=channels,
        reference=reference,
        epoch=None if frame.epoch is None else frame.epoch + offset,
        meta=dict(frame.meta, view=view),
        report=report if report is not None else Report(list(frame.report.entries)),
        estimates=estimates,
        maneuvers=tuple(m for m in maneuvers if m[1] > start and m[0] <= end),
    )


def grid_index(t: np.ndarray, rate: float) -> np.ndarray:
    """The grid point whose half-period ``[t_i - T/2, t_i + T/2)`` holds each time (``t`` from 0)."""
    return np.floor(np.asarray(t, float) * rate + 0.5).astype(np.int64)


def pick(t: np.ndarray, valid: np.ndarray, rate: float, n_grid: int) -> np.ndarray:
    """For each grid point, the index of the valid sample nearest it within half a period, else -1."""
    cand = np.flatnonzero(valid)
    b = grid_index(t[cand], rate)
    ok = (b >= 0) & (b < n_grid)
    cand, b = cand[ok], b[ok]
    dist = np.abs(t[cand] - b / rate)
    order = np.lexsort((cand, dist, b))  # by grid point, then nearest, then earlier
    first = np.r_[True, np.diff(b[order]) != 0] if len(b) else np.zeros(0, bool)
    out = np.full(n_grid, -1, np.int64)
    out[b[order][first]] = cand[order][first]
    return out


def resample(frame, rate: float):
    """``frame`` on the grid ``i / rate`` (module docstring); one report line per channel."""
    report = Report(list(frame.report.entries))  # the input frame's report stays as it was
    t = frame.t - frame.t[0]
    n_grid = int(min(t[-1] * rate + 0.5, 2.0**62)) + 1
    if not 2 <= n_grid <= 10 * len(t) + 10:
        shown = frame.meta.get("dataset") or frame.meta.get("source") or "dataset"
        raise ReplayError(
            f"{shown}: rate {rate:g} Hz gives {n_grid} grid point(s) over the {t[-1]:g} s of "
            f"{len(t)} samples; "
            + ("2 at least are needed" if n_grid < 2 else "more than 10 per sample would be nearly all masked")
        )
    grid = np.arange(n_grid) / rate  # from the first sample; the frame's own origin is kept below
    groups = []
    for group in (frame.channels, frame.reference):
        out = {}
        for name, ch in group.items():
            idx = pick(t, ch.valid, rate, n_grid)
            taken = idx >= 0
            values = np.full((n_grid,) + ch.values.shape[1:], np.nan)
            values[taken] = ch.values[idx[taken]]
            out[name] = Channel(
                values, ch.unit, ch.frame, taken, ch.components, ch.angles, ch.convention, ch.description
            )
            shift = float(np.max(np.abs(t[idx[taken]] - grid[taken]))) if taken.any() else 0.0
            n_valid, kept = int(ch.valid.sum()), int(taken.sum())
            kind = "reference" if group is frame.reference else "channel"
            report.add(
                "dropped",
                name,
                n_valid - kept,
                f"{kind} at {rate:g} Hz: {kept} of its {n_valid} valid samples taken (the nearest to each "
                f"grid point within ±{0.5 / rate:g} s; largest shift {shift:.3f} s), the rest not taken",
            )
            report.add(
                "masked",
                name,
                n_grid - kept,
                f"{kind} at {rate:g} Hz: grid points of the {n_grid} with no valid sample within half a period",
            )
        groups.append(out)
    view = dict(frame.meta.get("view") or {}, rate=rate, grid=n_grid)
    view.setdefault("offset_s", 0.0)
    view.setdefault("samples", [0, len(frame.t)])
    view.setdefault("of", len(frame.t))
    return _rebuild(frame, frame.t[0] + grid, groups[0], groups[1], 0.0, view, report)
