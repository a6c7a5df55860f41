"""Loading long logs (issue 23): the linear mask_jumps against the quadratic one it replaced, on
synthetic tracks with many jumps and on every real Bohai file; the heartbeat of a long load."""
import functools
import io
import logging
import time

import numpy as np
import pytest

from replay.adapters.bohai import load, mask_jumps, reference
from replay.adapters.bohai.reference import _reach
from replay.util.progress import Loading, load_stage

from test_bohai import ROWS


def oracle_chain(t, p, starts, ends, at_jump, jump_threshold, max_speed):
    """The dynamic programme as it was before issue 23: every block against every earlier one, O(n^2)."""
    best, prev = np.zeros(len(starts)), np.full(len(starts), -1)
    for k in range(len(starts)):
        if k:
            d = np.hypot(*(p[ends[:k]] - p[starts[k]]).T)
            ok = d <= _reach(t[starts[k]] - t[ends[:k]], jump_threshold, max_speed)
            if ok.any():
                cand = np.where(ok, best[:k], -1.0)
                prev[k] = k - 1 - int(np.argmax(cand[::-1]))
                best[k] = best[prev[k]]
        best[k] += ends[k] - starts[k] + 1
    return prev, best


def oracle_mask_jumps(*args, **kwargs):
    """mask_jumps with the quadratic programme."""
    linear = reference._best_chain
    reference._best_chain = oracle_chain
    try:
        return reference.mask_jumps(*args, **kwargs)
    finally:
        reference._best_chain = linear


def track(rng, n, jumps, kind):
    """A jittered 10 Hz track with ``jumps`` steps, out-and-back displacements or noise bursts."""
    t = np.cumsum(rng.uniform(0.05, 0.15, n))
    p = rng.normal(0, 1, (n, 2)).cumsum(0) * 0.05 + np.c_[np.arange(n) * 0.1, np.zeros(n)]
    for _ in range(jumps):
        a, length = int(rng.integers(0, n)), int(rng.integers(1, max(2, n // 5)))
        if kind == "step":
            p[a:] += rng.normal(0, 50, 2)
        elif kind == "spike":
            p[a:a + length] += rng.normal(0, 50, 2)
        else:
            p[a:a + length] = rng.normal(0, 300, (len(p[a:a + length]), 2))
    return t, p


@pytest.fixture(params=["default", "small-groups"])
def groups(request, monkeypatch):
    """The linear programme as it is, and with tiny chunks and coarse groups, so that small
    tracks go through every shortcut (the group boxes start 4 groups back)."""
    if request.param == "small-groups":
        monkeypatch.setattr(reference, "_best_chain",
                            functools.partial(reference._best_chain, chunk=2, coarse=3))
    return request.param


# the noise bursts (the oracle's costliest tracks, 15-20 s) are slow: the steps and spikes stay fast
@pytest.mark.parametrize("kind", ["step", "spike", pytest.param("noise", marks=pytest.mark.slow)])
def test_mask_jumps_equals_the_quadratic_oracle_with_many_jumps(kind, groups):
    rng = np.random.default_rng({"step": 1, "spike": 2, "noise": 3}[kind])
    masked = 0
    for _ in range(8):
        n = int(rng.integers(2, 1000))
        t, p = track(rng, n, int(rng.integers(0, 40)), kind)
        for args in ((5.0, 10.0, 10), (2.0, 3.0, 3), (5.0, 10.0, 1)):
            keep = mask_jumps(t, p, *args)
            assert np.array_equal(keep, oracle_mask_jumps(t, p, *args))
            masked += int((~keep).sum())
    assert masked > 500  # the cases do mask


def test_a_persistent_far_step_and_repeated_seams_equal_the_oracle(groups):
    # the slow shapes: a track that never comes back (its first half is what the chain keeps),
    # and a track repeated with seams (the benchmark's long log, in small)
    rng = np.random.default_rng(4)
    t, p = track(rng, 1200, 0, "step")
    p[500:] += 5000.0
    assert np.array_equal(mask_jumps(t, p), oracle_mask_jumps(t, p))
    far = np.concatenate([p[:600], p[600:] + 1e6, p[:600] + 3.0])  # away for good, then back near
    far_t = np.cumsum(np.full(len(far), 0.1))
    assert np.array_equal(mask_jumps(far_t, far), oracle_mask_jumps(far_t, far))
    seams = np.concatenate([p[:300]] * 5)
    ts = np.cumsum(np.full(len(seams), 0.1))
    keep = mask_jumps(ts, seams)
    assert np.array_equal(keep, oracle_mask_jumps(ts, seams)) and (~keep).sum() > 0


@pytest.mark.parametrize("name", sorted(ROWS))
def test_real_files_masks_equal_the_oracle(bohai_dir, name, monkeypatch):
    new = load(bohai_dir / name)
    monkeypatch.setattr(reference, "_best_chain", oracle_chain)
    old = load(bohai_dir / name)
    assert np.array_equal(new.reference["position"].valid, old.reference["position"].valid)
    assert np.array_equal(new.channels["gps_position"].valid, old.channels["gps_position"].valid)
    assert new.meta["jumps"] == old.meta["jumps"] and new.meta["gps"] == old.meta["gps"]
    assert new.report.lines() == old.report.lines()


def test_heartbeat_after_a_few_seconds_with_the_stage_and_its_eta():
    out = io.StringIO()
    with Loading("long.csv", 2_400_000_000, quiet=False, stream=out, after=0.05, every=0.05):
        load_stage("parsing the table", 0.25)
        time.sleep(0.3)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("load long.csv (2.40GB): ")
    assert "parsing the table (25 % of the work, ETA" in lines[0]
    assert lines[-1].startswith("load long.csv (2.40GB): done in ")
    assert not Loading.active


def test_heartbeat_silent_when_short_quiet_or_the_notes_are_off():
    out = io.StringIO()
    with Loading("short.csv", 10, quiet=False, stream=out, after=5.0):
        load_stage("reading", 0.0)
    with Loading("quiet.csv", 10, quiet=True, stream=out, after=0.0, every=0.01):
        time.sleep(0.05)
    log = logging.getLogger("replay")
    level = log.level
    log.setLevel(logging.WARNING)  # what -q does
    try:
        with Loading("q.csv", 10, stream=out, after=0.0, every=0.01):
            time.sleep(0.05)
    finally:
        log.setLevel(level)
    assert out.getvalue() == ""
    load_stage("no load in progress")  # nothing to talk to: no error
