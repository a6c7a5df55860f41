"""The fixed cost of one call of a compiled Kalman run loop, for comparing two versions of the code in
alternating processes (issue 37: the loops' packed arguments).

    .venv/bin/python benchmarks/bench_loop_call.py [--steps 100] [--calls 3000]

On ``sim/auv-sonar`` (``make_frame`` + the ``sonar`` task, as ``bench_filters.py``): the best of
``--calls`` direct calls of the EKF's and the UKF's compiled loop (``kalman_loops.ekf_run`` /
``sigma_run`` through the typed fast call, the arguments of one ``Filter.run`` captured and replayed),
and the best of ``--calls`` / 3 whole ``Filter.run`` calls, in µs. Short runs show the per-call
costs (argument typing, records, unboxing) that the per-step benchmarks average away. Nothing is
asserted.
"""

from __future__ import annotations

import argparse
import gc
import time

import numpy as np

from replay.filters import kalman_loops, make_filter
from replay.filters.compiled import loop_ready, loops
from replay.sim.auv_sonar import make_frame
from replay.tasks import make_task


def _best(fn, n: int) -> float:
    gc.disable()
    try:
        best = float("inf")
        for _ in range(n):
            t = time.perf_counter()
            fn()
            best = min(best, time.perf_counter() - t)
        return best * 1e6
    finally:
        gc.enable()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--calls", type=int, default=3000)
    a = ap.parse_args()
    for loop, sig in ((kalman_loops.sigma_run, kalman_loops.SIGMA_RUN), (kalman_loops.ekf_run, kalman_loops.EKF_RUN)):
        assert loop_ready(loop, sig, True)
    pb = make_task("sonar").build(make_frame(np.random.default_rng(1), steps=a.steps), np.random.default_rng(2))
    out = []
    for name, loop in (("ekf", kalman_loops.ekf_run), ("ukf", kalman_loops.sigma_run)):
        flt = make_filter(name)
        flt.run(pb.model, pb.z, pb.x0, pb.P0, None)  # binds the loop's fast call
        kernel = next(k for (lp, _), k in loops._bound.items() if lp is loop)
        entry, got = kernel.entry, {}

        def capture(*args, entry=entry):
            got["args"] = args[len(kernel.fns) :]
            return entry(*args)

        kernel.entry = capture
        flt.run(pb.model, pb.z, pb.x0, pb.P0, None)
        kernel.entry = entry
        out.append(f"{name}_call={_best(lambda: kernel(*got['args']), a.calls):.2f}us")
        out.append(f"{name}_run={_best(lambda: flt.run(pb.model, pb.z, pb.x0, pb.P0, None), a.calls // 3):.2f}us")
    print(" ".join(out))


if __name__ == "__main__":
    main()
