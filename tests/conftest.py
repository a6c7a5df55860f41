"""Shared fixtures: where the real data lives.

Real-data tests read ``../shared`` beside the checkout (the repository root's
parent holds ``main/`` and ``shared/``), or the directory named by the
environment variable ``REPLAY_SHARED``. When it is absent those tests skip.
"""
import os
from pathlib import Path

import pytest

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
