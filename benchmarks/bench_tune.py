"""``replay tune`` at the issue's size: 3 filters x 50 trials x 20 runs on a 1000-sample Bohai segment.

    .venv/bin/python benchmarks/bench_tune.py [--trials 50] [--runs 20] [--filters ekf,ukf,pf]
                     [--sequence 20220822_0_6] [--work DIR] [--workers K]

Tunes ``q_scale`` and ``r_scale`` of each filter (log ranges) on the ``position`` task of a Bohai
sequence at its own rate, trained on the first 1000 samples of its first 60 % and tested on the
first 1000 samples of the rest (``--train-segment 0.6 --first 1000``: ``--first`` applies after
the view), sequential trials (``--workers`` spreads each trial's runs over local processes), in
a fresh directory, and prints the wall time with the machine gauge. Target (issue 25): under
10 minutes on the project's 2-core machine. Nothing is asserted: it is a report.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from time import perf_counter

from gauge import Gauge

SHARED = Path(os.environ.get("REPLAY_SHARED", Path(__file__).resolve().parents[1].parent / "shared"))
TARGET_S = 600.0
SPACE = '[{f}]\nq_scale = "log[1e-3, 1e2]"\nr_scale = "log[1e-2, 1e2]"\n'  # per filter


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--filters", default="ekf,ukf,pf")
    ap.add_argument("--sequence", default="20220822_0_6")
    ap.add_argument("--work", type=Path, default=None)
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args()
    data = SHARED / "datasets" / "bohai"
    if not data.is_dir():
        sys.exit(f"bench_tune: no Bohai data in {data} (set REPLAY_SHARED)")
    gauge = Gauge("bench_tune")
    gauge.start()
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_tune_"))
    work.mkdir(parents=True, exist_ok=True)
    space = work / "space.toml"
    space.write_text("".join(SPACE.format(f=f) for f in args.filters.split(",")))
    out = work / "tune"
    cmd = [sys.executable, "-m", "replay.cli", "tune", f"bohai/{args.sequence}", "--data-dir", str(data),
           "--task", "position", "--first", "1000", "--train-segment", "0.6", "--filters", args.filters,
           "--space", str(space), "--trials", str(args.trials), "--runs", str(args.runs), "--out", str(out), "-q"]
    if args.workers:
        cmd += ["--workers", str(args.workers)]
    t0 = perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    wall = perf_counter() - t0
    print(res.stdout)
    if res.returncode:
        print(res.stderr, file=sys.stderr)
        sys.exit(res.returncode)
    n = len(args.filters.split(","))
    print(f"{n} filters x {args.trials} trials x {args.runs} runs, 1000 samples of {args.sequence}: {wall:.1f} s "
          f"({'PASS' if wall < TARGET_S else 'MISS'}: target {TARGET_S:.0f} s); output {out}")
    gauge.end()


if __name__ == "__main__":
    main()
