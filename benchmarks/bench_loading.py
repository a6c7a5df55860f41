"""Long-log loading: time per row and peak memory of the Bohai adapter from 100k to 5 M rows.

    .venv/bin/python benchmarks/bench_loading.py [--sizes 100000,500000,2000000,5000000]
                     [--sequence 20220822_0_6] [--work DIR] [--keep]

For each size N it writes a Bohai CSV of N rows: the sequence's data rows repeated, each copy's
``time`` shifted by the span so far plus the median step (times stay increasing; the track jumps
back to its start at every seam, so each seam is a jump of the navigation solution that the
adapter must mask). It then loads the file in a fresh process (``replay.adapters.bohai.load``)
and reads that process's wall and CPU time and its own peak resident set (``ru_maxrss``); ``base`` is
the peak of a process that imported the same modules and loaded nothing. The table gives rows,
file size, load time, µs per row (wall and CPU: on a busy machine the wall time measures the
load of the others), peak RSS, its excess over ``base`` per row, and the masked
samples. Target (issue 23): µs per row flat within 2x from the smallest to the largest size.
Nothing is asserted: it is a report.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from time import perf_counter

import numpy as np

from gauge import Gauge

SHARED = Path(os.environ.get("REPLAY_SHARED", Path(__file__).resolve().parents[1].parent / "shared"))
TIME_FIELD = "time"
FLAT = 2.0  # the target: largest / smallest time per row


def repeat_log(src: Path, rows: int, dest: Path) -> int:
    """Write ``rows`` data rows of ``src`` repeated (times shifted to stay increasing) to ``dest``;
    returns the number of seams (copies - 1)."""
    header, *lines = src.read_text(encoding="utf-8").splitlines()
    lines = [ln for ln in lines if ln.strip()]
    k = header.split(",").index(TIME_FIELD)
    fields = [ln.split(",") for ln in lines]
    before = [",".join(f[:k]) + "," for f in fields]
    after = ["," + ",".join(f[k + 1:]) if len(f) > k + 1 else "" for f in fields]
    time = np.array([float(f[k]) for f in fields])
    period = time[-1] - time[0] + float(np.median(np.diff(time)))
    copies = -(-rows // len(lines))
    with open(dest, "w", encoding="utf-8") as fh:
        fh.write(header + "\n")
        left = rows
        for c in range(copies):
            m = min(left, len(lines))
            shifted = time[:m] + c * period
            fh.writelines(f"{b}{x!r}{a}\n" for b, x, a in zip(before, shifted.tolist(), after))
            left -= m
    return copies - 1


CHILD = """
import json, resource, sys, time
from replay.adapters.bohai import load
t0, c0 = time.perf_counter(), time.process_time()
frame = None if sys.argv[1] == '-' else load(sys.argv[1])
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
out = {"wall": wall, "cpu": cpu, "maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}
if frame is not None:
    out.update(rows=len(frame), masked=int((~frame.reference["position"].valid).sum()),
               jumps=frame.meta["jumps"]["events"])
print(json.dumps(out))
"""


def measure(path: str) -> dict:
    """Load ``path`` ('-' for none) in a fresh process: wall time, peak RSS and what was masked."""
    res = subprocess.run([sys.executable, "-c", CHILD, path], capture_output=True, text=True)
    if res.returncode:
        raise SystemExit(f"loading {path} failed: {res.stderr.strip().splitlines()[-1:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="100000,500000,2000000,5000000")
    ap.add_argument("--sequence", default="20220822_0_6")
    ap.add_argument("--work", type=Path, help="directory for the generated CSVs (default: a temporary one)")
    ap.add_argument("--keep", action="store_true", help="keep the generated CSVs")
    args = ap.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",")]
    src = SHARED / "datasets" / "bohai" / f"{args.sequence}.csv"
    if not src.is_file():
        raise SystemExit(f"{src}: not found (set REPLAY_SHARED)")
    gauge = Gauge("bench_loading")
    gauge.start()
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_loading_"))
    work.mkdir(parents=True, exist_ok=True)
    base = measure("-")
    print(f"source {src.name}; base (imports only): peak RSS {base['maxrss_kb'] / 1024:.0f} MB")
    print(f"{'rows':>9} {'seams':>5} {'MB':>7} {'write s':>8} {'load s':>8} {'us/row':>7} {'CPU s':>7} "
          f"{'CPU us/row':>10} {'peak MB':>8} {'B/row':>6} {'masked':>8}")
    per_row, cpu_row = [], []
    try:
        for n in sizes:
            path = work / f"{args.sequence}_x{n}.csv"
            t0 = perf_counter()
            seams = repeat_log(src, n, path)
            written = perf_counter() - t0
            r = measure(str(path))
            us = 1e6 * r["wall"] / r["rows"]
            per_row.append(us)
            cpu_row.append(1e6 * r["cpu"] / r["rows"])
            extra = (r["maxrss_kb"] - base["maxrss_kb"]) * 1024 / r["rows"]
            print(f"{r['rows']:>9} {seams:>5} {path.stat().st_size / 1e6:>7.0f} {written:>8.1f} "
                  f"{r['wall']:>8.2f} {us:>7.2f} {r['cpu']:>7.2f} {cpu_row[-1]:>10.2f} "
                  f"{r['maxrss_kb'] / 1024:>8.0f} {extra:>6.0f} {r['masked']:>8}", flush=True)
            if not args.keep:
                path.unlink()
    finally:
        if not args.keep and args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    for what, xs in (("wall time", per_row), ("CPU time", cpu_row)):
        ratio = max(xs) / min(xs)
        print(f"{what} per row, largest / smallest: {ratio:.2f} (target <= {FLAT:g}: "
              f"{'PASS' if ratio <= FLAT else 'MISS'})")
    gauge.end()
    return 0


if __name__ == "__main__":
    sys.exit(main())
