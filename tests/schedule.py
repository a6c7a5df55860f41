"""The suite's schedule over pytest-xdist's workers: the costliest modules first (loaded by conftest.py).

The README's commands run ``-n auto --dist loadscope --no-loadscope-reorder`` (pyproject.toml): a
module runs whole in one worker (its module-scoped fixtures computed once), and the modules are
handed out in collection order, one at a time to whichever worker is nearly done. This plugin
collects the modules in decreasing declared cost (:data:`COST`: seconds measured in a clean-clone
CI run of the whole suite with coverage, cold kernel caches, per-test ``--durations=0``; the
undeclared modules cost less than every declared one and keep their order), so that a long module
never starts at the end while the other worker idles: the cheap modules fill the end on both
workers (longest first: the classical greedy schedule, within one module of the best).

Only the selected tests count: a module's slow tests (``-m slow``) and its other tests are
declared apart, so the quick check (``-m "not slow"``) is ordered by what it runs. The costs are
relative: a stale number only makes the order less good, never a test wrong.
"""

from __future__ import annotations

from pathlib import Path

import pytest

# module: (seconds of its tests not marked slow, seconds of its slow tests), in the whole suite
# (setup + call + teardown per test, summed; measured as this module's docstring says)
COST: dict[str, tuple[float, float]] = {}


def module_cost(name: str, slow_selected: bool, fast_selected: bool) -> float:
    fast, slow = COST.get(name, (0.0, 0.0))
    return (fast if fast_selected else 0.0) + (slow if slow_selected else 0.0)


def _module(item) -> str:
    return Path(item.nodeid.split("::", 1)[0]).name


@pytest.hookimpl(trylast=True)  # after the deselection by -m and -k: only what runs counts
def pytest_collection_modifyitems(session, config, items):
    slow: dict[str, bool] = {}
    fast: dict[str, bool] = {}
    for item in items:
        name = _module(item)
        if item.get_closest_marker("slow") is not None:
            slow[name] = True
        else:
            fast[name] = True
    cost = {n: module_cost(n, slow.get(n, False), fast.get(n, False)) for n in {**slow, **fast}}
    items.sort(key=lambda item: -cost[_module(item)])  # stable: the modules stay whole, in their order
