"""Bags/MCAP speed: read robot_localization/test1.bag into a frame (target < 2 s);
export a 10,000-step run with five filters to a Foxglove MCAP (target < 3 s).

    python benchmarks/bench_bags.py [--repeat 3]
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from time import perf_counter, process_time
from types import SimpleNamespace

import numpy as np

from replay.adapters import bags
from replay.outputs.export_mcap import write_mcap
from replay.frame import Channel, Frame

SHARED = Path(os.environ.get("REPLAY_SHARED", Path(__file__).resolve().parents[1].parent / "shared"))


def bench_read(repeat: int) -> float:
    path = SHARED / "datasets" / "bags" / "robot_localization" / "test1.bag"
    mapping = Path(__file__).resolve().parents[1] / "docs" / "mappings" / "rl_test1.toml"
    best = np.inf
    for _ in range(repeat):
        t0, c0 = perf_counter(), process_time()
        frame = bags.load(path, mapping=mapping)
        best, cpu = min(best, perf_counter() - t0), process_time() - c0
    print(f"read test1.bag (16,806 messages -> {len(frame)} samples): {best:.3f} s wall, {cpu:.3f} s CPU (target < 2 s, "
          f"{2.0 / best:.1f}x margin)")
    return best


def bench_export(repeat: int, n: int = 10_000, filters: int = 5) -> float:
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.1
    truth = np.cumsum(rng.standard_normal((n, 3)), axis=0)
    frame = Frame(t, {"dvl": Channel(rng.standard_normal((n, 3)), "m/s", components=("x", "y", "z")),
                      "depth": Channel(rng.standard_normal(n), "m")},
                  {"position": Channel(truth, "m")}, epoch=1.7e9,
                  meta={"crs": "EPSG:32651", "origin": [500000.0, 4500000.0], "origin_alt": 0.0})
    problem = SimpleNamespace(truth_position=truth, truth_valid=np.ones(n, bool), position_index=(0, 1, 2),
                              axis_names=("x", "y", "z"), angle_index={}, model=SimpleNamespace(x_angles=(3,)))
    est = {f"f{i}": {"t": t, "x": np.column_stack([truth + rng.standard_normal((n, 3)), rng.standard_normal(n)]),
                     "err": rng.standard_normal((n, 3))} for i in range(filters)}
    best = np.inf
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeat):
            t0, c0 = perf_counter(), process_time()
            count = write_mcap(Path(tmp) / "bench.mcap", frame, problem, est)
            best, cpu = min(best, perf_counter() - t0), process_time() - c0
        size = (Path(tmp) / "bench.mcap").stat().st_size
        print(f"export {n} steps x {filters} filters to MCAP ({count} messages, {size / 1e6:.1f} MB): "
              f"{best:.3f} s wall, {cpu:.3f} s CPU (target < 3 s, {3.0 / best:.1f}x margin)")
        validate(Path(tmp) / "bench.mcap")
    return best


def validate(path) -> None:
    """Run mcap-validate (Foxglove's TypeScript readers) on the exported file when installed."""
    from replay.data.registry import cache_dir

    tool = Path(os.environ.get("REPLAY_MCAP_VALIDATE_DIR", cache_dir() / "mcap-validate"))
    if shutil.which("node") is None or not (tool / "node_modules").is_dir():
        print(f"  mcap-validate: skipped (node or {tool}/node_modules missing)")
        return
    res = subprocess.run(["node", str(tool / "validate_mcap.js"), str(path)], capture_output=True, text=True)
    print("  mcap-validate:", (res.stdout.splitlines() or [res.stderr.strip()])[0][:160])


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    bench_read(args.repeat)
    bench_export(args.repeat)
