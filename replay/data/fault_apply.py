"""Applying injected faults (:mod:`replay.data.faults`) to a frame: a new frame, the input untouched.

:func:`apply` takes the checked specifications and the run's fault generator; fault ``k`` draws
from its own child stream (``rng.spawn``), so changing one fault's intensity changes no other
fault's draws. Each fault adds report lines and a ``meta["faults"]`` entry with its counts.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from replay.data import faults as decl
from replay.util.errors import ReplayError
from replay.frame import Report, Channel
from replay.util.seeds import FAULT, rng_for
from replay.data.views import pick


def apply(frame, specs, rng: np.random.Generator, source: str = "dataset"):
    """``frame`` with the faults ``specs`` (a value of the ``fault`` dataset parameter) applied;
    ``frame`` itself when there are none."""
    if not specs:
        return frame

    specs = decl.check(specs, source)
    streams = rng.spawn(len(specs))
    channels, report, counts = dict(frame.channels), Report(list(frame.report.entries)), []
    t = frame.t - frame.t[0]
    for spec, stream in zip(specs, streams):
        channel, kind, values = decl.parse(spec)
        target = _target(frame, channels, channel, spec, source)
        n_before = int(target.valid.sum())
        if kind in decl.MOVES:
            group = _companions(channels, channel)
            try:
                moved, done = _MOVE[kind](t, target.valid, values, stream)
            except ReplayError as e:
                raise ReplayError(f"{source}: fault {spec}: {e}") from None
            for name in group:
                channels[name] = _moved(channels[name], moved)
        else:
            with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused in _alter, not warned
                channels[channel], done = _alter(kind, t, target, values, stream, f"{source}: fault {spec}")
        left = int(channels[channel].valid.sum())
        if left == 0:
            raise ReplayError(f"{source}: fault {spec} removes every sample of channel {channel} ({n_before} valid)")
        entry = {"fault": spec, "channel": channel, "valid_before": n_before, "valid_after": left, **done}
        if kind in decl.MOVES:
            entry["channels"] = group
        counts.append(entry)
        _report(report, spec, channel, entry)
    meta = dict(frame.meta, faults=counts)
    return dataclasses.replace(frame, channels=channels, meta=meta, report=report)


def stream(rng) -> np.random.Generator:
    """The fault stream of ``registry.load_frame(rng=...)``: a seed S (None: 0) gives run 0's of
    ``replay eval --seed S`` (:data:`replay.util.seeds.FAULT`), a Generator a child of it."""
    if isinstance(rng, np.random.Generator):
        return rng.spawn(1)[0]
    return rng_for(0 if rng is None else int(rng), 0, FAULT)


def _target(frame, channels, channel, spec, source):
    if channel in channels:
        ch = channels[channel]
        if not ch.valid.any():
            raise ReplayError(f"{source}: fault {spec}: channel {channel} has no valid sample to fault")
        return ch
    where = " (a reference channel: faults apply to sensor channels only)" if channel in frame.reference else ""
    names = ", ".join(sorted(channels)) or "none"
    raise ReplayError(f"{source}: fault {spec}: no channel {channel!r}{where} (channels: {names})")


def _companions(channels, channel) -> list[str]:
    """The channel and those of the same message: named ``CHANNEL_...``, valid at the same samples."""
    valid = channels[channel].valid
    return [channel] + [
        n for n, c in channels.items() if n.startswith(channel + "_") and np.array_equal(c.valid, valid)
    ]


def _moved(ch, moved):
    """``ch`` with its valid samples moved: ``moved[i]`` is the new index of sample i, -1 lost."""
    values = np.full_like(ch.values, np.nan)
    valid = np.zeros(len(ch.valid), bool)
    src = np.flatnonzero(ch.valid & (moved >= 0))
    values[moved[src]] = ch.values[src]
    valid[moved[src]] = True
    return Channel(values, ch.unit, ch.frame, valid, ch.components, ch.angles, ch.convention, ch.description)


def _kept(valid, lose):
    """``moved`` for samples that stay in place but for ``lose``."""
    moved = np.where(valid & ~lose, np.arange(len(valid)), -1)
    return moved, {"dropped": int((valid & lose).sum())}


def _dropout(t, valid, v, rng):
    u = np.ones(len(valid))
    u[valid] = rng.random(int(valid.sum()))
    return _kept(valid, u < v["p"])


def _outage(t, valid, v, rng):
    since = t - v["t0"]
    inside = (since >= 0) & ((since % v["every"] if v["every"] else since) < v["d"])
    return _kept(valid, inside)


def _rate(t, valid, v, rng):
    gaps = np.diff(t[valid])
    if not len(gaps) or 1.0 / v["f"] <= gaps.min():  # a period below every gap: each sample keeps its point
        return _kept(valid, np.zeros(len(valid), bool))
    n_grid = int(t[-1] * v["f"] + 0.5) + 1
    if n_grid > 10 * len(t) + 10:  # as the rate view: a grid mostly empty (and its memory)
        raise ReplayError(
            f"{n_grid} grid points over {len(t)} samples; give a rate below "
            f"{10 * len(t) / max(t[-1], 1e-300):.3g} Hz (or at least 1 / the smallest gap between samples)"
        )
    idx = pick(t, valid, v["f"], n_grid)
    keep = np.zeros(len(valid), bool)
    keep[idx[idx >= 0]] = True
    return _kept(valid, ~keep)


def _shift(t, valid, dt):
    """Each valid sample to the stamp nearest ``t + dt`` (one past either end, or landing on a slot
    an earlier sample took, lost)."""
    src = np.flatnonzero(valid)
    new = t[src] + dt
    j = np.clip(np.searchsorted(t, new), 1, len(t) - 1)
    j = np.where(np.abs(t[j - 1] - new) <= np.abs(t[j] - new), j - 1, j)
    half = [t[1] - t[0], t[-1] - t[-2]] if len(t) > 1 else [0.0, 0.0]
    inside = (new >= t[0] - half[0] / 2) & (new <= t[-1] + half[1] / 2)
    _, first = np.unique(np.where(inside, j, -1), return_index=True)
    taken = np.zeros(len(src), bool)
    taken[first] = True
    ok = inside & taken
    moved = np.full(len(valid), -1)
    moved[src[ok]] = j[ok]
    err = float(np.max(np.abs(t[j[ok]] - new[ok]))) if ok.any() else 0.0
    return moved, {
        "dropped": int((~ok).sum()),
        "shifted": int((ok & (j != src)).sum()),
        "largest_stamp_error_s": err,
    }


def _delay(t, valid, v, rng):
    return _shift(t, valid, np.full(int(valid.sum()), v["d"]))


def _jitter(t, valid, v, rng):
    return _shift(t, valid, rng.normal(0.0, v["s"], int(valid.sum())))


def _clock_offset(t, valid, v, rng):
    return _shift(t, valid, v["c"] + v["skew"] * 1e-6 * t[valid])


_MOVE = {
    "dropout": _dropout,
    "outage": _outage,
    "rate": _rate,
    "delay": _delay,
    "jitter": _jitter,
    "clock_offset": _clock_offset,
}


def _alter(kind, t, ch, v, rng, owner):
    """(the channel with its values altered, the counts)."""
    x = ch.values.reshape(len(ch.values), -1).copy()
    idx = np.flatnonzero(ch.valid)
    width = x.shape[1]
    if kind == "outliers":
        u = rng.random(len(idx))
        if v["jump"] is not None:
            d = rng.normal(size=(len(idx), width))
            err = v["jump"] * d / np.linalg.norm(d, axis=1, keepdims=True)
        else:
            err = v["s"] * rng.standard_t(v["df"], size=(len(idx), width))
        hit = u < v["p"]
        x[idx[hit]] += err[hit]
        changed = idx[hit]
    elif kind in ("bias", "drift"):
        idx = idx[t[idx] >= v["t0"]]
        if kind == "bias":
            b = np.asarray(v["b"], float)
            if len(b) not in (1, width):
                raise ReplayError(
                    f"{owner}: b holds {len(b)} values, the channel has {width} component(s): give one or {width}"
                )
            x[idx] += b
        else:
            dt = np.diff(t[idx], prepend=t[idx[0]] if len(idx) else 0.0)
            x[idx] += np.cumsum(v["s"] * np.sqrt(dt)[:, None] * rng.normal(size=(len(idx), width)), axis=0)
        changed = idx
    elif kind == "scale":
        x[idx] *= v["k"]
        changed = idx
    else:  # quantize
        before = x[idx].copy()
        x[idx] = np.round(x[idx] / v["step"]) * v["step"]
        changed = idx[np.any(x[idx] != before, axis=1)]
    if not np.isfinite(x[idx]).all():
        raise ReplayError(f"{owner}: makes values of the channel non-finite (overflow); give a smaller value")
    values = x.reshape(ch.values.shape)
    out = Channel(values, ch.unit, ch.frame, ch.valid.copy(), ch.components, ch.angles, ch.convention, ch.description)
    return out, {"altered": int(len(changed))}


def _report(report, spec, channel, entry):
    for action in ("dropped", "altered", "shifted"):
        if action not in entry:
            continue
        n = entry[action]
        extra = (
            f"; largest difference from the moved stamp {entry['largest_stamp_error_s']:.4f} s"
            if action == "shifted"
            else ""
        )
        whole = f" (with {', '.join(entry['channels'][1:])})" if len(entry.get("channels", [])) > 1 else ""
        report.add(action, channel, n, f"fault {spec}{whole}: {entry['valid_after']} valid samples left{extra}")
