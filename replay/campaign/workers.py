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
"""
from __future__ import annotations

import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _pdeathsig(sig: int) -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

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
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
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
