"""Bohai CSV adapter speed: read each 20220822 log of ../shared into a frame (target < 1 s each).

    .venv/bin/python benchmarks/bench_bohai.py [--repeat 2]

The check moved here from tests/test_bohai.py: a timing is a report, not a unit test.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path
from time import perf_counter, process_time

from replay.adapters.bohai import load

SHARED = Path(os.environ.get("REPLAY_SHARED", Path(__file__).resolve().parents[1].parent / "shared"))
TARGET_S = 1.0


def bench_load(path: Path, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0, c0 = perf_counter(), process_time()
        frame = load(path)
        best, cpu = min(best, perf_counter() - t0), process_time() - c0
    verdict = "PASS" if best < TARGET_S else "MISS"
    print(f"{path.name}: {len(frame)} rows in {best:.3f} s wall (best of {repeat}), {cpu:.3f} s CPU; "
          f"target < {TARGET_S:g} s: {verdict} ({TARGET_S / best:.1f}x margin)")
    return best


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    files = sorted((SHARED / "datasets" / "bohai").glob("20220822_*.csv"))
    if not files:
        raise SystemExit(f"no Bohai logs under {SHARED}/datasets/bohai")
    for path in files:
        bench_load(path, args.repeat)
