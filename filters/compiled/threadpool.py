"""Threads for compiled kernels that release the GIL: how many, and one contiguous range each.

:func:`split` runs a kernel that takes a ``start, stop`` index range on
:func:`threads` threads. Each index (a Monte Carlo run, a particle, ...) is
computed by one thread with the same arithmetic, so the numbers do not depend
on the thread count. ``REPLAY_THREADS`` sets the count (default: the CPUs this
process may use, at most 8); campaign and reproduction workers set it to 1
(:mod:`replay.campaign.workers`), so N worker processes on N cores do not each
start N threads.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

_pool = None
_pool_size = 0


def threads() -> int:
    n = os.environ.get("REPLAY_THREADS")
    if n:
        return max(1, int(n))
    return max(1, min(8, len(os.sched_getaffinity(0))))


def _get_pool(n: int) -> ThreadPoolExecutor:
    global _pool, _pool_size
    if _pool is None or _pool_size < n:
        _pool, _pool_size = ThreadPoolExecutor(n, thread_name_prefix="replay-kernel"), n
    return _pool


def split(kernel, total: int, *args, grain: int = 1) -> list:
    """``kernel(*args, start, stop)`` over 0 .. total - 1, in one contiguous range per thread
    (``kernel`` may also be a Python function that calls kernels), at least ``grain`` indices
    per thread: waking a thread costs tens of microseconds, more than small ranges take.
    Returns the ranges' results in index order."""
    n = min(threads(), total // max(grain, 1))
    if n <= 1:
        return [kernel(*args, 0, total)]
    pool = _get_pool(n)
    size = (total + n - 1) // n
    futures = [pool.submit(kernel, *args, j * size, min(total, (j + 1) * size)) for j in range(1, n)]
    first = kernel(*args, 0, min(total, size))  # the calling thread takes the first range
    return [first] + [fut.result() for fut in futures]
