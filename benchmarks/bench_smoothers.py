"""Time of the factor-graph smoothers on test1.bag's fusion task (issue 39: gtsam-batch under 30 s on 2 cores).

    python benchmarks/bench_smoothers.py [--data ../shared/datasets/bags/robot_localization/test1.bag] [--repeat 2]

Builds the problem once (docs/mappings/rl_test1_fusion.toml: 16,806 steps), then runs each row
``--repeat`` times on it, printing the wall time and the process's CPU time of each run (the CPU
time is what the machine's load does not inflate), and the LM iterations of gtsam-batch.
"""
import argparse
import time
from pathlib import Path

import numpy as np

from replay.filters import make_filter
from replay.filters.noise_params import apply
from replay.run.pipeline import build_problem

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=str(ROOT.parent / "shared/datasets/bags/robot_localization/test1.bag"))
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--rows", default="gtsam-batch,gtsam-lag,ekf")
    a = ap.parse_args()
    cfg = dict(dataset=a.data, dataset_params={"mapping": str(ROOT / "docs/mappings/rl_test1_fusion.toml")},
               first=None, task="fusion", task_params={}, filter="-", filter_params={}, seed=0,
               alignment="se3", divergence_threshold=None, adapter=None)
    p = build_problem(cfg, 0)
    print(f"test1.bag fusion: {p.z.shape[0]} steps, state {p.model.nx}")
    for name in a.rows.split(","):
        flt = make_filter(name)
        model, P0 = apply(flt, p.model, p.P0[None])
        for r in range(a.repeat):
            w, c = time.perf_counter(), time.process_time()
            est = flt.run_batch(model, p.z[None], p.x0[None], P0, [np.random.default_rng(0)])[0]
            w, c = time.perf_counter() - w, time.process_time() - c
            extra = f", {est.info['iterations']} LM iterations" if "iterations" in est.info else ""
            print(f"{name} run {r}: {w:.2f} s wall, {c:.2f} s CPU{extra}")


if __name__ == "__main__":
    main()
