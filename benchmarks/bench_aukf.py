"""AUKF vs UKF time per step on paper 001's model (10 states, 8 measurements).

Target (issue 5): AUKF at most 2x our UKF's time per step. Run:
    /work/venv/bin/python benchmarks/bench_aukf.py
"""
import time

import numpy as np

from replay.filters.aukf import AUKF
from replay.filters.sigma import UKF
from replay.sim.sauv_current import make_frame
from replay.tasks.dead_reckoning import DeadReckoningTask


def per_step(flt, pb, repeat=5):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        est = flt.run(pb.model, pb.z, pb.x0, pb.P0)
        best = min(best, (time.perf_counter() - t0) / len(pb.z))
    return best, est


def main():
    fr = make_frame(np.random.default_rng(0))
    pb = DeadReckoningTask().build(fr, np.random.default_rng(1))
    u, _ = per_step(UKF(), pb)
    a, est = per_step(AUKF(), pb)
    off, _ = per_step(AUKF(adapt=False), pb)
    print(f"model: nx={pb.model.nx}, nz={pb.model.nz}, steps={len(pb.z)}")
    print(f"UKF            {u * 1e6:8.1f} us/step")
    print(f"AUKF           {a * 1e6:8.1f} us/step   ratio {a / u:.2f}  (guard fired Q {est.info['guard_q']}, R {est.info['guard_r']})")
    print(f"AUKF adapt=off {off * 1e6:8.1f} us/step   ratio {off / u:.2f}")


if __name__ == "__main__":
    main()
