"""The machine-load gauge every benchmark prints at its start and end, and thread limits.

A timing on a shared machine means little without the state of the machine
beside it. :class:`Gauge` prints, at the start and at the end of a benchmark:

* the load average (1, 5, 15 min) and the CPU count;
* a fixed arithmetic speed gauge: the best of 15 evaluations of ``sin(a)``,
  ``cos(a)`` and their ``arctan2`` on the same 100,000 values (single-threaded
  NumPy, no BLAS, into buffers allocated once: no page faults), in ms. It reads
  the same on the same machine in the same state: a larger figure at the end
  than at the start means the machine slowed down during the run;
* a threads gauge: the time of one small compiled parallel loop (numba ``prange``, about 50 µs of
  square roots on one thread) on every numba thread over its time on one thread. On a quiet
  machine it is well below 1; when another process keeps a core busy, the threads wait for each
  other at the end of every parallel loop, for a whole scheduler time slice, and the ratio reaches
  tens (seen on 2026-11-22: 4 ms on 2 threads against 54 µs on one; IGWO-STCPF 7.2 ms per step
  on 2 threads, 0.98 ms on one). Above 1, every figure measured on several threads is meaningless;
* at the end, the share of the machine's CPU time that *other* processes used
  during the run: busy time of the whole machine (``/proc/stat``) minus this
  process's CPU time and that of its reaped children, over the machine's total.
  Above 10 % the run is flagged noisy.

:func:`threads` limits, around a timed call, the threads of numba (``numba.set_num_threads``),
of BLAS (``threadpoolctl``) and of the library (``REPLAY_THREADS``, read at call time).

Benchmark helper only: the library never imports it.
"""
from __future__ import annotations

import contextlib
import os
import resource
import time

import numba as nb
import numpy as np

NOISY = 0.10  # share of the CPU used by other processes above which a run is flagged


def loadavg():
    try:
        return tuple(round(v, 2) for v in os.getloadavg())
    except OSError:  # pragma: no cover
        return None


def cpu_ticks():
    """(busy, total) clock ticks of the whole machine since boot (``/proc/stat``), or None."""
    try:
        with open("/proc/stat") as fh:
            v = [int(t) for t in fh.readline().split()[1:9]]
    except (OSError, ValueError):
        return None
    return sum(v) - v[3] - v[4], sum(v)  # minus idle and iowait


def own_cpu_s() -> float:
    """CPU seconds of this process and of its children that have been waited for."""
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def others_share(busy_ticks: float, total_ticks: float, own_s: float, hz: float):
    """Share of the machine's CPU time used by other processes: (busy - own) / total, clipped at 0;
    None when no time passed."""
    if total_ticks <= 0:
        return None
    return max(0.0, (busy_ticks - own_s * hz) / total_ticks)


def speed_gauge(repeat: int = 15) -> float:
    """Seconds of a fixed arithmetic workload (best of ``repeat``): lower = faster machine state."""
    a = np.linspace(-3.0, 3.0, 100_000)
    s, c, r = np.empty_like(a), np.empty_like(a), np.empty_like(a)
    best = np.inf
    for _ in range(repeat):  # into buffers allocated once: arithmetic only (a fresh 800 kB array
        t0 = time.perf_counter()  # costs page faults until malloc's mmap threshold has grown)
        np.sin(a, out=s)
        np.cos(a, out=c)
        np.arctan2(s, c, out=r)
        best = min(best, time.perf_counter() - t0)
    return best


@nb.njit(parallel=True, cache=True)
def _region(a, out):
    for c in nb.prange(out.shape[0]):
        s = 0.0
        for i in range(c, a.shape[0], out.shape[0]):
            s += np.sqrt(a[i])
        out[c] = s


def threads_gauge(calls: int = 100) -> tuple[float, float, int]:
    """(seconds of one parallel loop on every numba thread, on one thread, the thread count): best of
    ``calls`` each, after a warm-up call (compiled once, then loaded from numba's cache)."""
    a, out = np.linspace(1.0, 2.0, 20_000), np.empty(8)
    n = nb.config.NUMBA_NUM_THREADS
    old = nb.get_num_threads()
    res = []
    try:
        for t in (n, 1):
            nb.set_num_threads(t)
            _region(a, out)
            best = np.inf
            for _ in range(calls):
                t0 = time.perf_counter()
                _region(a, out)
                best = min(best, time.perf_counter() - t0)
            res.append(best)
    finally:
        nb.set_num_threads(old)
    return res[0], res[1], n


def _threads_text(all_s, one_s, n):
    q = all_s / one_s
    warn = "  -- THREADS WAIT FOR EACH OTHER: figures on several threads are meaningless" if q > 1.0 else ""
    return f"threads gauge {all_s * 1e6:.0f} µs on {n} threads / {one_s * 1e6:.0f} µs on 1 = {q:.2f}{warn}"


def verdict(measured, limit, higher_is_better: bool = False) -> str:
    """PASS when ``measured`` meets ``limit`` (<= limit, or >= when ``higher_is_better``), MISS
    otherwise; n/a when nothing was measured (None or NaN)."""
    if measured is None or not np.isfinite(measured):
        return "n/a"
    ok = measured >= limit if higher_is_better else measured <= limit
    return "PASS" if ok else "MISS"


class Gauge:
    """``g = Gauge("bench_x"); g.start()`` ... ``g.end()``: the machine's state at both ends of a run."""

    def __init__(self, name: str):
        self.name = name
        self.info = {}

    def start(self) -> dict:
        self.t0, self.ticks0, self.cpu0 = time.perf_counter(), cpu_ticks(), own_cpu_s()
        tg = threads_gauge()
        self.info.update(loadavg_start=loadavg(), cpu_count=os.cpu_count(), gauge_ms_start=speed_gauge() * 1e3,
                         threads_gauge_start=tg)
        print(f"[machine] {self.name} start: load average {self.info['loadavg_start']} on "
              f"{self.info['cpu_count']} CPUs; speed gauge {self.info['gauge_ms_start']:.3f} ms "
              f"(sin, cos, atan2 of 100,000 values, best of 15; lower = faster); {_threads_text(*tg)}", flush=True)
        return self.info

    def end(self) -> dict:
        """Print and return the end state (also in ``self.info``); the run's wall time included."""
        gauge_ms = speed_gauge() * 1e3  # before the CPU accounting: the gauges' own CPU is ours
        tg = threads_gauge()
        wall = time.perf_counter() - self.t0
        end, own = cpu_ticks(), own_cpu_s() - self.cpu0
        share = None
        if self.ticks0 is not None and end is not None:
            share = others_share(end[0] - self.ticks0[0], end[1] - self.ticks0[1], own, os.sysconf("SC_CLK_TCK"))
        self.info.update(loadavg_end=loadavg(), gauge_ms_end=gauge_ms, threads_gauge_end=tg, others_cpu_share=share,
                         wall_s=wall)
        other = "n/a" if share is None else f"{100 * share:.0f} %"
        noisy = share is not None and share > NOISY
        print(f"[machine] {self.name} end: load average {self.info['loadavg_end']}; speed gauge {gauge_ms:.3f} ms "
              f"(start {self.info['gauge_ms_start']:.3f}); {_threads_text(*tg)}; other processes used {other} "
              f"of the machine's CPU "
              f"during the run{'  -- NOISY: rerun on a quiet machine' if noisy else ''}; wall time {wall:.1f} s",
              flush=True)
        return self.info


@contextlib.contextmanager
def threads(n: int):
    """Run the body on ``n`` threads: numba's (``set_num_threads``, at most its pool size), BLAS's
    (``threadpoolctl``) and the library's (``REPLAY_THREADS``). Yields the numba thread count used."""
    import numba

    old_env = os.environ.get("REPLAY_THREADS")
    old_nb = numba.get_num_threads()
    nb_n = max(1, min(n, numba.config.NUMBA_NUM_THREADS))
    os.environ["REPLAY_THREADS"] = str(n)
    numba.set_num_threads(nb_n)
    try:
        with blas_limit(n):
            yield nb_n
    finally:
        numba.set_num_threads(old_nb)
        if old_env is None:
            os.environ.pop("REPLAY_THREADS", None)
        else:
            os.environ["REPLAY_THREADS"] = old_env


def blas_limit(n: int):
    """``threadpoolctl.threadpool_limits(n)`` (a project dependency); a no-op context when it is missing
    (:func:`have_threadpoolctl` says which)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return contextlib.nullcontext()
    return threadpool_limits(limits=n)


def have_threadpoolctl() -> bool:
    import importlib.util

    return importlib.util.find_spec("threadpoolctl") is not None


BLAS_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
            "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def thread_env(n: int, base=None) -> dict:
    """An environment for a subprocess limited to ``n`` threads before any import (BLAS variables,
    ``NUMBA_NUM_THREADS`` is left alone: ``set_num_threads`` needs the pool; ``REPLAY_THREADS``)."""
    env = dict(os.environ if base is None else base)
    env.update({k: str(n) for k in BLAS_ENV})
    env["REPLAY_THREADS"] = str(n)
    return env
