"""Seed streams: every random number of a run comes from a generator derived from the master seed.

With :class:`numpy.random.SeedSequence` and the user's seed ``S``:

* ``(S, run, 0)``: the dataset (a simulator's truth and sensor noise);
* ``(S, run, 1)``: the task (synthesised measurement noise, the prior draw);
* ``(S, run, 2, crc32(filter name))``: the filter's own randomness;
* ``(S, run, 3)``: injected faults (:mod:`replay.data.faults`; one child stream per fault).

So in a given run every filter sees the same measurements (common random
numbers: paired comparisons have tight intervals), and adding a filter changes
no other filter's numbers.
"""

from __future__ import annotations

import zlib

import numpy as np

DATA, TASK, FILTER, FAULT = 0, 1, 2, 3


def rng_for(seed: int, run: int, *stream: int) -> np.random.Generator:
    """The generator of stream ``stream`` of run ``run`` under master seed ``seed``."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(run), *stream]))


def filter_stream(name: str) -> int:
    """The stream number of a filter: crc32 of its name."""
    return zlib.crc32(name.encode())


def filter_rng(seed: int, run: int, name: str) -> np.random.Generator:
    """The filter ``name``'s generator in run ``run``."""
    return rng_for(seed, run, FILTER, filter_stream(name))
