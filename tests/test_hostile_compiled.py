"""The compiled machinery's fence (filters/compiled/; docs/architecture.md, "How a compiled step
is called"): one file touches numba's internals, and a plugin's engine that changes a step is
never replaced by a whole-run loop that computes the library's steps instead."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hostile import register

from replay.filters import kalman_loops
from replay.filters.compiled import loop_ready
from replay.filters.kalman import own_steps
from replay.filters.sigma import UKF, SigmaEngine
from replay.models.random_walk import RandomWalkPosition

register("compiled-plugin-engine-changes-predict")

ROOT = Path(__file__).resolve().parents[1]
# the acceptance grep of issue 26, written in pieces so that this file does not match it
INTERNALS = re.compile("|".join(["_numba" "_type_", "__wrapper" "_address__", "over" "loads", "_cache" r"(\.|_file)",
                                 "_umath" "_linalg"]))


def test_two_files_reach_into_numba_or_numpy_internals():
    """numba_internals for the compiled machinery; replay.util.kernel_cache for numba's cache files
    (imported by the model kernels too, which may import only replay.util)."""
    hits = sorted(str(p.relative_to(ROOT)) for d in ("replay", "filters", "adapters", "benchmarks", "tests")
                  for p in (ROOT / d).rglob("*.py") if INTERNALS.search(p.read_text()))
    assert hits == ["filters/compiled/numba_internals.py", "replay/util/kernel_" "cache" ".py"]


class Inflating(SigmaEngine):
    """A plugin's engine: the UKF's prediction with the covariance inflated."""

    def predict(self, x, P, k):
        x, P = super().predict(x, P, k)
        return x, P * 1.5


class InflatingUKF(UKF):
    def engine(self, model, rngs):
        return Inflating(self, model, rngs)


@pytest.mark.slow  # the UKF's run loop compiled when numba's cache lacks it (~12 s, once per machine)
def test_an_engine_that_changes_a_step_steps_in_python():
    assert own_steps(SigmaEngine.__new__(SigmaEngine)) and not own_steps(Inflating.__new__(Inflating))
    assert loop_ready(kalman_loops.sigma_run, kalman_loops.SIGMA_RUN, True)  # the loop would run
    model = RandomWalkPosition(0.5 * np.eye(3), np.diag([1.0, 2.0, 0.5]))
    Z = np.cumsum(np.random.default_rng(3).normal(size=(2, 30, 3)), axis=1)
    X0, P0 = Z[:, 0] + 0.1, np.stack([np.eye(3)] * 2)
    rngs = [np.random.default_rng(m) for m in range(2)]
    plain, mine = UKF().run_batch(model, Z, X0, P0, rngs), InflatingUKF().run_batch(model, Z, X0, P0, rngs)
    for a, b in zip(plain, mine):
        assert np.all(np.diagonal(b.P, axis1=-2, axis2=-1) > np.diagonal(a.P, axis1=-2, axis2=-1))


def test_every_module_with_cached_kernels_imports_the_cache_guard():
    """numba's cache of a function is locked and sealed only once replay.util.kernel_cache is imported:
    every module defining ``cache=True`` functions imports it first (a model's kernels may be the first
    thing a process compiles, before any filter is imported)."""
    missing = []
    for d in ("replay", "filters", "adapters"):
        for p in (ROOT / d).rglob("*.py"):
            text = p.read_text()
            if "cache=True" in text and p.stem not in ("kernel_cache", "copies"):
                if "from replay.util import kernel_cache" not in text:
                    missing.append(str(p.relative_to(ROOT)))
    assert missing == []
