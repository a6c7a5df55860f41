"""Shared fixtures: where the real data lives, and a temporary cache per session.

Real-data tests read ``../shared`` beside the checkout (the repository root's
parent holds ``main/`` and ``shared/``), or the directory named by the
environment variable ``REPLAY_SHARED``. When it is absent those tests skip.

The session runs with ``REPLAY_CACHE_DIR`` set to a fresh temporary directory
(removed at the end), set here before any test module imports numba, so the
registry's user cache is empty (tests name their data directories) and nothing
is read from or written to the developer's cache. Subprocesses inherit it.
The compiled kernels (``filters/compiled/copies.py`` keeps them in ``$REPLAY_CACHE_DIR/kernels``)
survive from one session to the next: the session's ``kernels`` directory starts
as a copy of this checkout's test kernel store (``<user cache>/test-kernels/<hash
of the checkout's path>``, owner-only) and is merged into it at the end
(tests/kernel_store.py; pytest-xdist's workers share the session's cache, below). The store is
the product's own cache, used as the product uses it: every copy is named by the
hash of its text (the template, its helpers and the model's kernels), checked
against it before it is imported, and numba's files are sealed and checked
before they are read; an edit to a kernel gives a new name and a compilation,
never stale machine code. ``REPLAY_TEST_CACHE_DIR=DIR`` keeps the whole cache in
DIR across sessions instead (no store); ``REPLAY_TEST_FRESH_KERNELS=1`` starts the
session with no kernels (every kernel compiled, as on a clean machine).

Scratch space (``tmp_path`` and the session cache) is on a RAM file system when ``/dev/shm`` is one
with room to spare (``PYTEST_DEBUG_TEMPROOT``, pytest's own setting, names it; set it to keep them
elsewhere). The product syncs every file it publishes and optuna's SQLite study every commit, as it
must; on the CI machine's disk a sync costs 2-8 ms and the quick check makes thousands of them
(measured 2026-11-29, loaded machine: tests/test_tune*.py 50 s -> 31 s wall, the same CPU). The
syncs still run: only their wait is gone.
"""
import os
import shutil
import sys
import tempfile
import threading
from pathlib import Path

import pytest

import kernel_store
from replay.data.registry import cache_dir as _user_cache


def _ram_temp_root() -> str | None:
    """``/dev/shm`` when it is a writable tmpfs with at least 2 GiB free, else None."""
    shm = "/dev/shm"
    try:
        st = os.statvfs(shm)
        with open("/proc/mounts") as mounts:
            tmpfs = any(ln.split()[1:3] == [shm, "tmpfs"] for ln in mounts if len(ln.split()) > 2)
    except OSError:
        return None
    return shm if tmpfs and os.access(shm, os.W_OK) and st.f_bavail * st.f_frsize >= 2 << 30 else None


if not os.environ.get("PYTEST_DEBUG_TEMPROOT") and (_RAM := _ram_temp_root()):
    os.environ["PYTEST_DEBUG_TEMPROOT"] = _RAM  # read by pytest's tmp_path_factory (and by xdist's workers)
_TEMP_ROOT = os.environ.get("PYTEST_DEBUG_TEMPROOT") or None

pytest_plugins = ["schedule"]  # the costliest modules first over the xdist workers (tests/schedule.py)

# the MCAP validator is looked for in the user cache (tests/test_export_mcap.py): keep finding it there
os.environ.setdefault("REPLAY_MCAP_VALIDATE_DIR", str(_user_cache() / "mcap-validate"))
_KEEP = os.environ.get("REPLAY_TEST_CACHE_DIR")
# Under pytest-xdist the workers use the session cache of the process that started them (inherited in the
# environment): a kernel one worker compiled is loaded by the other instead of compiled again (on a clean
# clone every copy was compiled once per worker). The cache is made for processes sharing it (issue 33:
# tests/test_kernel_cache_concurrency.py); the process that made it restores, saves and removes it.
_SHARED = os.environ.get("REPLAY_TEST_SESSION_CACHE") if os.environ.get("PYTEST_XDIST_WORKER") else None
_OWNER = not _KEEP and not _SHARED
if _KEEP:
    SESSION_CACHE = Path(_KEEP).expanduser()
elif _SHARED:
    SESSION_CACHE = Path(_SHARED)
else:
    SESSION_CACHE = Path(tempfile.mkdtemp(prefix="replay-tests-", dir=_TEMP_ROOT))
    os.environ["REPLAY_TEST_SESSION_CACHE"] = str(SESSION_CACHE)
KERNEL_STORE = kernel_store.store_for(_user_cache(), Path(__file__).resolve().parents[1])
if _OWNER and os.environ.get("REPLAY_TEST_FRESH_KERNELS") != "1":
    kernel_store.restore(KERNEL_STORE, SESSION_CACHE / "kernels")
os.environ["REPLAY_CACHE_DIR"] = str(SESSION_CACHE)



def _untraced_child():
    """A process forked from a test (a campaign's, tune's or reproduction's pool) runs untraced: with
    ``--cov`` it inherited coverage's tracer, which slowed every job and numba compilation it ran by
    about a third, and what it measured was lost at the worker's exit (coverage follows no fork here)."""
    sys.settrace(None)
    threading.settrace(None)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_untraced_child)


@pytest.fixture(scope="session", autouse=True)
def _untraced_compilation():
    """Under ``--cov``, numba compiles untraced: coverage stops at the start of an outermost
    compilation (numba's ``numba:compile`` event) and starts again at its end. Numba's compiler is
    Python (type inference, lowering) and coverage's tracer slowed a compile-heavy module by about
    an eighth (tests/test_compiled.py + test_smoothers.py on cold caches: 149 -> 130 s).

    What it leaves unmeasured, never more: a restarted tracer knows none of the frames running
    when it starts, so the rest of the functions under way at the end of a compilation (e.g.
    ``loop_ready``'s lines after ``loop.compile``) is not counted unless they run again later, nor
    the package's lines numba calls inside a compilation (the cache locator's, in
    ``replay.util.kernel_cache``); on test_smoothers.py, 18 lines of 22k. (Hooking the same tracer
    back in place instead, keeping its stack of frames, counted lines in functions that had not
    run: refused.) Only the main thread's compilations pause it (coverage starts again on the
    calling thread only); a thread running beside one loses its measurement from then on. The
    package declares no ``@overload``, ``@intrinsic`` or ``generated_jit``, whose Python would run
    inside a compilation."""
    import coverage

    cov = coverage.Coverage.current()
    if cov is None:  # no --cov
        yield
        return
    from numba.core import event

    class Pause(event.Listener):  # the main thread's compilations (cov.start hooks the calling thread)
        depth = 0

        def on_start(self, ev):
            if threading.current_thread() is threading.main_thread():
                self.depth += 1
                if self.depth == 1:
                    cov.stop()

        def on_end(self, ev):
            if threading.current_thread() is threading.main_thread():
                self.depth -= 1
                if self.depth == 0:
                    cov.start()

    listener = Pause()
    event.register("numba:compile", listener)
    yield
    event.unregister("numba:compile", listener)


CHECKOUT = Path(__file__).resolve().parents[1]
_NOT_OUTPUTS = {".pytest_cache", "__pycache__", ".coverage", ".hypothesis", ".ruff_cache"}


def checkout_entries(root: Path = CHECKOUT) -> set:
    """The checkout's top-level entries and ``runs/<dataset>/<task>`` (where ``replay eval`` writes
    by default), as relative paths."""
    out = {n for n in os.listdir(root) if n not in _NOT_OUTPUTS and not n.endswith(".egg-info")}
    runs = root / "runs"
    for a in os.listdir(runs) if runs.is_dir() else []:
        out.add(f"runs/{a}")
        if (runs / a).is_dir():
            out.update(f"runs/{a}/{b}" for b in os.listdir(runs / a))
    return out


def pytest_sessionstart(session):
    session.config.checkout_before = checkout_entries()


def pytest_sessionfinish(session, exitstatus):
    """The suite leaves the checkout as it found it (issue 40: empty directories under runs/): tests
    write in tmp_path. Whatever appeared in the checkout fails the session, named (the controller
    only, under pytest-xdist)."""
    before = getattr(session.config, "checkout_before", None)
    if before is None or hasattr(session.config, "workerinput"):
        return
    new = sorted(checkout_entries() - before)
    if new:
        import sys

        sys.stderr.write(
            f"\nthe tests left {len(new)} new entries in the checkout {CHECKOUT} (tests must write in "
            f"tmp_path): {', '.join(new[:20])}\n"
        )
        session.exitstatus = 1


def pytest_unconfigure(config):
    if _OWNER:  # after the workers (pytest-xdist's controller ends last)
        kernel_store.save(SESSION_CACHE / "kernels", KERNEL_STORE)
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
