"""Shared fixtures: where the real data lives, and a temporary cache per session.

Real-data tests read ``../shared`` beside the checkout (the repository root's
parent holds ``main/`` and ``shared/``), or the directory named by the
environment variable ``REPLAY_SHARED``. When it is absent those tests skip.

The session runs with ``REPLAY_CACHE_DIR`` set to a fresh temporary directory
(removed at the end), set here before any test module imports numba: the
paper-002 kernels (``filters/compiled/copies.py`` writes them to
``$REPLAY_CACHE_DIR/kernels``) are compiled once per session from the current
sources and never read from a developer's cache, and the registry's user cache
is empty (tests name their data directories). ``REPLAY_TEST_CACHE_DIR=DIR``
keeps that cache in DIR across sessions instead. Subprocesses inherit it.
Tests that compile the paper-002 filter kernels are marked ``slow``; ``pytest -m "not slow"`` compiles
only the models' small gufuncs (replay/models/kernel_model.py, about 2 s once, cached by numba).
"""
import os
import shutil
import tempfile
from pathlib import Path

import pytest

from replay.registry import cache_dir as _user_cache

# the MCAP validator is looked for in the user cache (tests/test_export_mcap.py): keep finding it there
os.environ.setdefault("REPLAY_MCAP_VALIDATE_DIR", str(_user_cache() / "mcap-validate"))
_KEEP = os.environ.get("REPLAY_TEST_CACHE_DIR")
SESSION_CACHE = Path(_KEEP).expanduser() if _KEEP else Path(tempfile.mkdtemp(prefix="replay-tests-"))
os.environ["REPLAY_CACHE_DIR"] = str(SESSION_CACHE)


def pytest_unconfigure(config):
    if not _KEEP:
        shutil.rmtree(SESSION_CACHE, ignore_errors=True)


SKIP_REASON = "../shared/datasets not found: real-data tests need the shared data beside the checkout"


def shared_path() -> Path:
    """``$REPLAY_SHARED`` if set, else ``../shared`` relative to the repository root."""
    env = os.environ.get("REPLAY_SHARED")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    path = shared_path()
    if not (path / "datasets").is_dir():
        pytest.skip(SKIP_REASON)
    return path


@pytest.fixture(scope="session")
def bohai_dir(shared_dir) -> Path:
    path = shared_dir / "datasets" / "bohai"
    if not path.is_dir():
        pytest.skip(SKIP_REASON)
    return path


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """With ``REPLAY_REQUIRE_SHARED=1`` (set by .ci/run) a test skipped for want of
    ``../shared`` data fails instead: CI must always run the real-data tests.
    Skips for other reasons (e.g. no Node.js for the MCAP validator) stay skips."""
    outcome = yield
    rep = outcome.get_result()
    if rep.skipped and os.environ.get("REPLAY_REQUIRE_SHARED") == "1":
        reason = str(rep.longrepr)
        if "shared" in reason.lower() and "node" not in reason.lower():
            rep.outcome = "failed"
            rep.longrepr = f"REPLAY_REQUIRE_SHARED=1 but the test was skipped: {reason}"
