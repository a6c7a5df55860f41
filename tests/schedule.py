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

# module: (seconds of its tests not marked slow, seconds of its slow tests), setup + call + teardown
# summed per module; the modules of 3 s or more
COST: dict[str, tuple[float, float]] = {
    "test_kernel_cache_concurrency.py": (0, 2223),
    "test_new_user.py": (0, 596),
    "test_hostile_kernel_cache.py": (20, 314),
    "test_reproduce_002.py": (1, 303),
    "test_trajectory_evo.py": (1, 298),
    "test_fusion_identity.py": (42, 160),
    "test_compiled.py": (0, 189),
    "test_fusion.py": (34, 115),
    "test_reproduce_001.py": (10, 130),
    "test_smoothers.py": (105, 23),
    "test_tune.py": (36, 85),
    "test_builtin_cases.py": (1, 107),
    "test_hostile_rundirs.py": (9, 89),
    "test_reproduce_003.py": (4, 92),
    "test_export_mcap.py": (27, 61),
    "test_tune_repeat.py": (10, 62),
    "test_paper002.py": (6, 65),
    "test_fusion_noise.py": (66, 0),
    "test_hostile_rerun.py": (7, 58),
    "test_plain_python.py": (0, 62),
    "test_report_browser_recorded.py": (0, 58),
    "test_honest_defaults.py": (4, 54),
    "test_bags.py": (14, 40),
    "test_score_api.py": (6, 46),
    "test_campaign.py": (9, 43),
    "test_recorded.py": (12, 40),
    "test_batched.py": (14, 36),
    "test_cli.py": (6, 43),
    "test_rerun_old_manifest.py": (46, 0),
    "test_tune_study.py": (35, 12),
    "test_gtsam_smoothing.py": (1, 40),
    "test_progress.py": (4, 36),
    "test_aukf.py": (40, 0),
    "test_fusion_doc.py": (32, 0),
    "test_report_browser.py": (0, 30),
    "test_bohai_loading.py": (9, 21),
    "test_hostile_score.py": (29, 0),
    "test_trajectory_lengths.py": (2, 27),
    "test_aukf_premise.py": (12, 16),
    "test_parameter_counts.py": (27, 0),
    "test_eval_options.py": (6, 19),
    "test_outputs_safety.py": (5, 19),
    "test_fusion_heading.py": (5, 19),
    "test_score_cli.py": (1, 22),
    "test_notebook.py": (0, 20),
    "test_export_safety.py": (0, 20),
    "test_reference_provenance.py": (20, 0),
    "test_reproduce_000.py": (4, 16),
    "test_plugins.py": (11, 7),
    "test_score_plot.py": (3, 16),
    "test_report.py": (4, 14),
    "test_consistency_band.py": (17, 0),
    "test_hostile_inputs.py": (16, 0),
    "test_campaign_workers.py": (4, 12),
    "test_export_foxglove.py": (13, 0),
    "test_outages.py": (3, 10),
    "test_verdict.py": (13, 0),
    "test_reproduce_pool.py": (0, 13),
    "test_marks.py": (12, 0),
    "test_tuned_views.py": (12, 0),
    "test_pipeline.py": (1, 11),
    "test_hostile_tune.py": (11, 0),
    "test_api.py": (4, 8),
    "test_views.py": (10, 0),
    "test_numeric_homes.py": (1, 9),
    "test_datasets_info.py": (5, 5),
    "test_fusion_loops.py": (0, 10),
    "test_tasks_inputs.py": (4, 6),
    "test_kernel_cache_writers.py": (9, 0),
    "test_params.py": (0, 9),
    "test_wfpf.py": (8, 0),
    "test_trials_archive.py": (2, 6),
    "test_score_prepare.py": (7, 0),
    "test_hostile_export.py": (7, 0),
    "test_hostile_http.py": (0, 6),
    "test_tuned_paths.py": (0, 6),
    "test_gpf.py": (6, 0),
    "test_hostile_adapters.py": (6, 0),
    "test_faults.py": (1, 5),
    "test_fast_reader.py": (5, 0),
    "test_hostile_outputs.py": (5, 0),
    "test_kernel_cache_records.py": (5, 0),
    "test_output_set.py": (5, 0),
    "test_eval_runs.py": (4, 0),
    "test_fetch.py": (3, 1),
    "test_pf_proposal.py": (3, 1),
    "test_full_covariance.py": (4, 0),
    "test_mounts.py": (4, 0),
    "test_reproduce_declared.py": (3, 0),
    "test_p002_speed.py": (0, 3),
    "test_hostile_campaign.py": (3, 0),
    "test_mcap_bulk.py": (3, 0),
    "test_report_recorded.py": (2, 1),
    "test_hostile_fetch.py": (3, 0),
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
