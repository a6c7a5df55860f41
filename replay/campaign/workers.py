"""Local pool workers that end with the campaign process.

A ``ProcessPoolExecutor`` worker blocks reading its call queue; when the main
process is killed with SIGKILL it gets no shutdown message, and, since its sibling
workers still hold the queue's pipe open, it would wait forever as an orphan.
:func:`init_worker` (the pool's initializer) makes each worker end when the
process that started it dies:

* Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` — the kernel kills the worker the
  moment its parent (the thread that forked it, here the main thread of the
  campaign process) exits; then the parent pid is checked once, in case the parent
  died before the call;
* elsewhere (or if prctl is unavailable): a daemon thread compares
  ``os.getppid()`` with the original parent's pid every ``poll`` seconds and calls
  ``os._exit`` when it has changed (the worker was re-parented).

The initializer also limits each worker's BLAS threads (``threadpoolctl``) to
cores // workers: OpenBLAS otherwise starts one thread per core in every worker,
and two workers on two cores then run four spinning threads.

Workers only compute (the main process writes every result), so ending them
abruptly loses nothing that a resumed campaign does not compute again.

:func:`connect_scheduler` connects a Dask client to a remote scheduler within a
bounded time (distributed leaves the comm handshake unbounded).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from contextlib import contextmanager

from replay.util.errors import ReplayError
import multiprocessing as mp
from concurrent.futures import ProcessPoolExecutor
import asyncio
import ctypes

from threadpoolctl import threadpool_limits

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _pdeathsig(sig: int) -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent_pid: int, poll: float) -> None:
    while os.getppid() == parent_pid:
        time.sleep(poll)
    os._exit(1)


_limits = None  # the BLAS thread limit of this worker, kept alive


def limit_threads(n: int) -> None:
    """At most ``n`` BLAS/OpenMP threads in this process (``threadpoolctl``), so that
    N workers on N cores do not each start N threads that compete for the cores."""
    global _limits
    _limits = threadpool_limits(limits=n)


def init_worker(parent_pid: int, blas_threads: int | None = None, poll: float = 0.5) -> None:
    """Pool initializer: end this worker when ``parent_pid`` (the campaign process) dies;
    limit its BLAS threads to ``blas_threads`` when given."""
    if blas_threads:
        limit_threads(blas_threads)
        os.environ["REPLAY_THREADS"] = str(blas_threads)  # the compiled filter kernels' threads
    if not _pdeathsig(signal.SIGKILL):
        threading.Thread(target=_watch, args=(parent_pid, poll), daemon=True, name="parent-watch").start()
    if os.getppid() != parent_pid:  # the parent died before the watch was set
        os._exit(1)


def start_method() -> str:
    """fork on Linux (workers start with everything the parent imported), spawn elsewhere."""
    return "fork" if sys.platform == "linux" and "fork" in mp.get_all_start_methods() else "spawn"


def worker_threads(n: int) -> int:
    """The BLAS and compiled-kernel threads of each worker of a pool of ``n``: cores // n."""
    return max(1, (os.cpu_count() or 1) // n)


def process_pool(n: int):
    """A process pool of ``n`` of our workers (:func:`init_worker`): each ends with this process
    and gets :func:`worker_threads` BLAS and compiled-kernel threads, so n workers on n cores do
    not run n² threads. Campaigns and reproductions both start theirs here."""
    return ProcessPoolExecutor(
        max_workers=n,
        mp_context=mp.get_context(start_method()),
        initializer=init_worker,
        initargs=(os.getpid(), worker_threads(n)),
    )


@contextmanager
def like_a_worker(n: int):
    """For its duration, this process's BLAS and compiled-kernel threads are those of a worker of a
    pool of ``n`` (:func:`worker_threads`): a job run here takes the workers' code paths (a filter
    picks its kernels by its thread count: one thread and a single run, the plain kernel instead of the
    OpenMP one, which compiles 8 s longer and a worker would never call)."""
    k, before = worker_threads(n), os.environ.get("REPLAY_THREADS")
    os.environ["REPLAY_THREADS"] = str(k)
    try:
        with threadpool_limits(limits=k):
            yield
    finally:
        if before is None:
            os.environ.pop("REPLAY_THREADS", None)
        else:
            os.environ["REPLAY_THREADS"] = before


def connect_scheduler(address: str, timeout: float):
    """A ``distributed.Client`` of the scheduler at ``address``, or a one-line ReplayError
    naming the address and ``timeout`` (seconds) when it does not answer within it.

    ``Client(address, timeout=...)`` bounds the TCP connect and the registration, but not
    the comm handshake in between (``distributed.comm.core.connect`` awaits the peer's
    handshake with no limit): anything that accepts the connection and never answers
    would hold ``campaign run`` for ever. So the handshake is made first, on a private
    event loop under ``asyncio.wait_for`` (1.25 ``timeout`` + 0.1 s at most); only a peer
    that answered it as a Dask scheduler is then given to ``Client`` (``timeout`` again).
    Not covered: a scheduler that answers this handshake and stalls on the next one.
    """
    # lazy: optional, dask's distributed is the [campaign] extra
    from distributed import Client  # noqa: PLC0415
    from distributed.comm import connect  # noqa: PLC0415

    async def handshake():  # connect() gives up on the TCP connection itself after `timeout`
        comm = await asyncio.wait_for(connect(address, timeout=timeout), 1.25 * timeout + 0.1)
        await comm.close()

    def refuse(why: str):
        return ReplayError(f"Dask scheduler {address}: no answer within {timeout:g} s ({why})")

    try:
        asyncio.run(handshake())
    except (asyncio.TimeoutError, TimeoutError):
        raise refuse("it accepted the connection but sent no handshake") from None
    except OSError as err:  # refused until the timeout, unknown host, ...
        raise refuse(
            err.strerror or ("nothing accepted the connection" if "Timed out" in str(err) else type(err).__name__)
        ) from None
    except ValueError as err:
        raise ReplayError(f"Dask scheduler {address}: not a scheduler address ({err})") from None
    except Exception as err:  # noqa: BLE001 — whatever answered is not a Dask scheduler
        raise ReplayError(
            f"Dask scheduler {address}: the answer is not a Dask handshake ({type(err).__name__})"
        ) from None
    try:
        return Client(address, timeout=f"{timeout}s", set_as_default=False)
    except (OSError, TimeoutError) as err:
        raise refuse(type(err).__name__) from None
