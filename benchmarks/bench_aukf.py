"""AUKF vs UKF time per step on paper 001's model (10 states, 8 measurements).

Target (issue 5): AUKF at most 2x our UKF's time per step. The filters are
timed alternately (best of ``repeat`` whole runs each), so a busy shared
machine slows both alike. Run:
    python benchmarks/bench_aukf.py
"""
import time

import numpy as np

from replay.filters.p001.aukf import AUKF
from replay.filters.sigma import UKF
from replay.sim.sauv_current import make_frame
from replay.tasks.dead_reckoning import DeadReckoningTask


def main(repeat=9):
    fr = make_frame(np.random.default_rng(0))
    pb = DeadReckoningTask().build(fr, np.random.default_rng(1))
    filters = {"UKF": UKF(), "AUKF (guard biased)": AUKF(), "AUKF (guard previous)": AUKF(guard="previous"),
               "AUKF (guard clip)": AUKF(guard="clip"), "AUKF adapt=off": AUKF(adapt=False)}
    best = dict.fromkeys(filters, np.inf)
    info = {}
    for _ in range(repeat):
        for name, flt in filters.items():
            t0 = time.perf_counter()
            est = flt.run(pb.model, pb.z, pb.x0, pb.P0)
            best[name] = min(best[name], (time.perf_counter() - t0) / len(pb.z))
            info[name] = est.info
    u = best["UKF"]
    print(f"model: nx={pb.model.nx}, nz={pb.model.nz}, steps={len(pb.z)}, best of {repeat} runs")
    for name, t in best.items():
        g = info[name]
        guards = f"  (guard fired Q {g['guard_q']}, R {g['guard_r']})" if "guard_q" in g else ""
        print(f"{name:22s} {t * 1e6:8.1f} us/step   ratio {t / u:.2f}{guards}")


if __name__ == "__main__":
    main()
