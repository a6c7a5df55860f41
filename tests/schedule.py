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
by CI (``.ci/run`` with ``PYTEST_ADDOPTS=--durations=0``: a clean clone, cold kernel caches, with
coverage) on the 2-core machine while it was shared (wall seconds per test, about 2.5 times a quiet
machine's); remeasure so when a module's cost changes much.
"""

from __future__ import annotations

from pathlib import Path

import pytest

# module (file name without .py): (seconds of its tests not marked slow, seconds of its slow tests), setup + call + teardown
# summed per module; the modules of 3 s or more
COST: dict[str, tuple[float, float]] = {
    "test_kernel_cache_concurrency": (0, 2223),
    "test_new_user": (0, 596),
    "test_hostile_kernel_cache": (20, 314),
    "test_reproduce_002": (1, 303),
    "test_trajectory_evo": (1, 298),
    "test_fusion_identity": (42, 160),
    "test_compiled": (0, 189),
    "test_fusion": (34, 115),
    "test_reproduce_001": (10, 130),
    "test_smoothers": (105, 23),
    "test_tune": (36, 85),
    "test_builtin_cases": (1, 107),
    "test_hostile_rundirs": (9, 89),
    "test_reproduce_003": (4, 92),
    "test_export_mcap": (27, 61),
    "test_tune_repeat": (10, 62),
    "test_paper002": (6, 65),
    "test_fusion_noise": (66, 0),
    "test_hostile_rerun": (7, 58),
    "test_plain_python": (0, 62),
    "test_report_browser_recorded": (0, 58),
    "test_honest_defaults": (4, 54),
    "test_bags": (14, 40),
    "test_score_api": (6, 46),
    "test_campaign": (9, 43),
    "test_recorded": (12, 40),
    "test_batched": (14, 36),
    "test_cli": (6, 43),
    "test_rerun_old_manifest": (46, 0),
    "test_tune_study": (35, 12),
    "test_gtsam_smoothing": (1, 40),
    "test_progress": (4, 36),
    "test_aukf": (40, 0),
    "test_fusion_doc": (32, 0),
    "test_report_browser": (0, 30),
    "test_bohai_loading": (9, 21),
    "test_hostile_score": (29, 0),
    "test_trajectory_lengths": (2, 27),
    "test_aukf_premise": (12, 16),
    "test_parameter_counts": (27, 0),
    "test_eval_options": (6, 19),
    "test_outputs_safety": (5, 19),
    "test_fusion_heading": (5, 19),
    "test_score_cli": (1, 22),
    "test_notebook": (0, 20),
    "test_export_safety": (0, 20),
    "test_reference_provenance": (20, 0),
    "test_reproduce_000": (4, 16),
    "test_plugins": (11, 7),
    "test_score_plot": (3, 16),
    "test_report": (4, 14),
    "test_consistency_band": (17, 0),
    "test_hostile_inputs": (16, 0),
    "test_campaign_workers": (4, 12),
    "test_export_foxglove": (13, 0),
    "test_outages": (3, 10),
    "test_verdict": (13, 0),
    "test_reproduce_pool": (0, 13),
    "test_marks": (12, 0),
    "test_tuned_views": (12, 0),
    "test_pipeline": (1, 11),
    "test_hostile_tune": (11, 0),
    "test_api": (4, 8),
    "test_views": (10, 0),
    "test_numeric_homes": (1, 9),
    "test_datasets_info": (5, 5),
    "test_fusion_loops": (0, 10),
    "test_tasks_inputs": (4, 6),
    "test_kernel_cache_writers": (9, 0),
    "test_params": (0, 9),
    "test_wfpf": (8, 0),
    "test_trials_archive": (2, 6),
    "test_score_prepare": (7, 0),
    "test_hostile_export": (7, 0),
    "test_hostile_http": (0, 6),
    "test_tuned_paths": (0, 6),
    "test_gpf": (6, 0),
    "test_hostile_adapters": (6, 0),
    "test_faults": (1, 5),
    "test_fast_reader": (5, 0),
    "test_hostile_outputs": (5, 0),
    "test_kernel_cache_records": (5, 0),
    "test_output_set": (5, 0),
    "test_eval_runs": (4, 0),
    "test_fetch": (3, 1),
    "test_pf_proposal": (3, 1),
    "test_full_covariance": (4, 0),
    "test_mounts": (4, 0),
    "test_reproduce_declared": (3, 0),
    "test_p002_speed": (0, 3),
    "test_hostile_campaign": (3, 0),
    "test_mcap_bulk": (3, 0),
    "test_report_recorded": (2, 1),
    "test_hostile_fetch": (3, 0),
}


def module_cost(name: str, slow_selected: bool, fast_selected: bool) -> float:
    fast, slow = COST.get(name, (0.0, 0.0))
    return (fast if fast_selected else 0.0) + (slow if slow_selected else 0.0)


def _module(item) -> str:
    return Path(item.nodeid.split("::", 1)[0]).stem


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
