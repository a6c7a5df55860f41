"""The suite's schedule over pytest-xdist's workers: the costliest modules first (loaded by conftest.py).

The README's commands run ``-n auto --dist loadscope --no-loadscope-reorder`` (pyproject.toml): a
module runs whole in one worker (its module-scoped fixtures computed once), and the modules are
handed out in collection order, one at a time to whichever worker is nearly done. This plugin
collects the modules in decreasing declared cost (:data:`COST`, in worker seconds; the undeclared
modules cost less than every declared one and keep their order), so that a long module
never starts at the end while the other worker idles: the cheap modules fill the end on both
workers (longest first: the greedy schedule).

Only the selected tests count: a module's slow tests (``-m slow``) and its other tests are
declared apart, so the quick check (``-m "not slow"``) is ordered by what it runs. The costs are
relative: a stale number only makes the order less good, never a test wrong. Measured 2026-11-29
on the shared 2-core machine under load (per-test durations: the quick check on warm kernels scaled
to its CPU seconds, the slow tests on cold kernels divided by the load, about 3.5): remeasure with
``--durations=0`` on a quiet machine when a module's cost changes much.
"""

from __future__ import annotations

from pathlib import Path

import pytest

# module: (seconds of its tests not marked slow, seconds of its slow tests), setup + call + teardown
# summed per module; the modules of 2 s or more
COST: dict[str, tuple[float, float]] = {
    "test_kernel_cache_concurrency.py": (0, 668),
    "test_compiled.py": (0, 297),
    "test_hostile_kernel_cache.py": (7, 85),
    "test_fusion.py": (3, 65),
    "test_tune.py": (3, 54),
    "test_cli.py": (1, 41),
    "test_export_mcap.py": (2, 29),
    "test_campaign.py": (2, 29),
    "test_fusion_identity.py": (8, 22),
    "test_hostile_rundirs.py": (4, 27),
    "test_outputs_safety.py": (1, 26),
    "test_export_safety.py": (0, 25),
    "test_eval_options.py": (0, 23),
    "test_bags.py": (5, 12),
    "test_gtsam_smoothing.py": (0, 14),
    "test_campaign_workers.py": (1, 13),
    "test_hostile_rerun.py": (8, 5),
    "test_honest_defaults.py": (0, 11),
    "test_hostile_score.py": (10, 0),
    "test_smoothers.py": (9, 0),
    "test_hostile_adapters.py": (9, 0),
    "test_paper002.py": (1, 7),
    "test_builtin_cases.py": (0, 7),
    "test_api.py": (0, 7),
    "test_hostile_inputs.py": (7, 0),
    "test_fusion_noise.py": (4, 0),
    "test_aukf.py": (4, 0),
    "test_outages.py": (1, 3),
    "test_hostile_api.py": (4, 0),
    "test_tune_study.py": (4, 0),
    "test_hostile_tune.py": (3, 0),
    "test_recorded.py": (3, 0),
    "test_reproduce_000.py": (3, 0),
    "test_reproduce_001.py": (3, 0),
    "test_house_rules.py": (3, 0),
    "test_reference_provenance.py": (3, 0),
    "test_plugins.py": (3, 0),
    "test_p002_speed.py": (0, 3),
    "test_export_foxglove.py": (3, 0),
    "test_faults.py": (1, 2),
    "test_wfpf.py": (3, 0),
    "test_tasks_inputs.py": (2, 0),
    "test_hostile_http.py": (0, 2),
}


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
