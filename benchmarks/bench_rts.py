"""The RTS smoothers' cost against their forward pass (issue 39, item 5: at most 1.5x).

    .venv/bin/python benchmarks/bench_rts.py [--repeat 5] [--runs 100] [--steps 2000] [--long 20000]
                     [--fusion] [--filters ekf,ukf,ckf]

For each filter, on ``sim/auv-sonar`` (6 states, 3 measurements, the model's compiled kernels):

* **batch**: ``--runs`` Monte Carlo runs of ``--steps`` steps in one ``Filter.run_batch``;
* **long**: one run of ``--long`` steps (a recording's length: test1.bag's fusion task has 16,806);
* with ``--fusion``: the fusion task of ``robot_localization/test1.bag``
  (``docs/mappings/rl_test1_fusion.toml``: 1 to 3 of 6 components measured per step, Q per step).

Timed: the forward pass (``Filter.run_batch`` of the filter) and the backward pass
(:func:`replay.filters.smoothers.backward_pass` on the forward pass's estimates), each the best
of ``--repeat`` interleaved rounds after a warm-up (compiled loops loaded), gc off while timed.
Printed: µs per run-step of each and the ratio backward / forward against the target 1.5
(PASS/MISS), and (forward + backward) / forward, what a ``+rts`` row costs against its filter.
Nothing is asserted; the machine gauge at the start and the end.
"""

from __future__ import annotations

import argparse
import gc
import os
import time
from pathlib import Path

import numpy as np

from gauge import Gauge, verdict

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("REPLAY_SHARED", ROOT.parent / "shared"))
BAG = SHARED / "datasets" / "bags" / "robot_localization" / "test1.bag"
MAPPING = ROOT / "docs" / "mappings" / "rl_test1_fusion.toml"
RATIO_MAX = 1.5


def sonar(runs: int, steps: int):
    from replay.sim.auv_sonar import make_frame
    from replay.tasks import make_task

    task = make_task("sonar")
    return [
        task.build(make_frame(np.random.default_rng(10 + r), steps=steps), np.random.default_rng(20 + r))
        for r in range(runs)
    ]


def fusion():
    from replay.adapters import bags
    from replay.tasks import make_task

    return [make_task("fusion").build(bags.load(BAG, mapping=MAPPING), np.random.default_rng(0))]


def timed(name: str, pbs, repeat: int):
    """(forward s, backward s) per run-step, best of ``repeat``."""
    from replay.filters import make_filter, smoothers

    fwd, sm = make_filter(name), make_filter(name + "+rts")
    model = pbs[0].model
    Z, X0, P0 = (np.stack([getattr(p, a) for p in pbs]) for a in ("z", "x0", "P0"))

    def forward():
        return fwd.run_batch(model, Z, X0, P0, [np.random.default_rng(0) for _ in pbs])

    out = forward()  # warm-up: the loops compiled or loaded
    X = np.ascontiguousarray([e.x for e in out])
    P = np.ascontiguousarray([e.P for e in out])
    assert not any(e.diverged for e in out), name
    smoothers.backward_pass(sm, model, X, P)
    best_f = best_b = np.inf
    gc.disable()
    try:
        for _ in range(repeat):
            t0 = time.perf_counter()
            forward()
            t1 = time.perf_counter()
            _, _, bad, _ = smoothers.backward_pass(sm, model, X, P)
            t2 = time.perf_counter()
            assert bad < 0, name
            best_f, best_b = min(best_f, t1 - t0), min(best_b, t2 - t1)
    finally:
        gc.enable()
    work = len(pbs) * len(pbs[0].z)
    return best_f / work, best_b / work


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--long", type=int, default=20000)
    ap.add_argument("--fusion", action="store_true")
    ap.add_argument("--filters", default="ekf,ukf,ckf")
    a = ap.parse_args()
    g = Gauge("bench_rts")
    g.start()
    cases = [(f"sim/auv-sonar {a.runs} runs x {a.steps} steps", sonar(a.runs, a.steps))]
    cases.append((f"sim/auv-sonar 1 run x {a.long} steps", sonar(1, a.long)))
    if a.fusion:
        cases.append(("test1.bag fusion task (16,806 steps)", fusion()))
    print(f"{'case':50s} {'filter':6s} {'forward':>10s} {'backward':>10s} {'bwd/fwd':>8s} {'(f+b)/f':>8s}")
    for title, pbs in cases:
        for name in a.filters.split(","):
            f, b = timed(name, pbs, a.repeat)
            r = b / f
            print(
                f"{title:50s} {name:6s} {f * 1e6:8.2f}µs {b * 1e6:8.2f}µs {r:8.2f} {(f + b) / f:8.2f}  "
                f"target bwd/fwd <= {RATIO_MAX}: {verdict(r, RATIO_MAX)}",
                flush=True,
            )
    g.end()


if __name__ == "__main__":
    main()
