"""replay's MCAP bulk writer (replay/outputs/mcap_bulk.py) against the ``mcap`` library's writer.

    .venv/bin/python benchmarks/bench_mcap_writer.py [--messages 200000,1000000] [--channels 8]
                     [--window 65536] [--compression zstd]

The export's load: ``--channels`` channels of equal rate, payloads of 60-140 bytes (a protobuf pose
or a JSON row), fed in time windows of about ``--window`` messages as ``McapOut`` does. Each writer
runs in a fresh process (``os.wait4``: its own peak resident set) and gets the same payloads, lists
of bytes per channel and window: the bulk writer takes them in one ``add_messages`` call per channel
and window, ``mcap.writer.Writer`` one ``add_message`` per message in log-time order (the order the
bulk writer writes). Printed: seconds spent in the writer's calls (payload generation left out), the
time per message, peak RSS, file size, and whether both files hold the same messages (read back with
``mcap``'s reader). Nothing is asserted: it is a report, quoted in mcap_bulk.py's docstring.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from time import perf_counter

import numpy as np


def windows(n: int, channels: int, window: int):
    """(per channel: log times, payloads) for each window; deterministic (seeded)."""
    rng = np.random.default_rng(0)
    per = n // channels
    step = max(1, window // channels)
    for lo in range(0, per, step):
        m = min(step, per - lo)
        out = []
        for c in range(channels):
            t = (np.arange(lo, lo + m, dtype=np.int64) * 100_000_000 + c * 1_000) + 1_700_000_000_000_000_000
            lens = rng.integers(60, 141, m)
            buf = rng.integers(0, 256, int(lens.sum()), dtype=np.uint8).tobytes()
            ends = np.cumsum(lens)
            out.append((t, [buf[e - k : e] for e, k in zip(ends.tolist(), lens.tolist())]))
        yield out


def run_bulk(path: Path, args) -> float:
    from replay.outputs.mcap_bulk import BulkWriter

    spent = 0.0
    w = BulkWriter(path, compression=args.compression, chunk_size=4 << 20)
    sid = w.register_schema("bench.Bytes", "jsonschema", b'{"type": "object"}')
    ids = [w.register_channel(f"/c{c}", "json", sid) for c in range(args.channels)]
    for win in windows(args.messages, args.channels, args.window):
        t0 = perf_counter()
        for cid, (t, data) in zip(ids, win):
            w.add_messages(cid, t, data)
        w.flush()
        spent += perf_counter() - t0
    t0 = perf_counter()
    w.finish()
    return spent + perf_counter() - t0


def run_library(path: Path, args) -> float:
    from mcap.writer import CompressionType, Writer

    spent = 0.0
    fh = open(path, "wb")
    w = Writer(fh, chunk_size=4 << 20, compression=CompressionType[args.compression.upper() or "NONE"])
    w.start(profile="", library="bench")
    sid = w.register_schema("bench.Bytes", "jsonschema", b'{"type": "object"}')
    ids = [w.register_channel(f"/c{c}", "json", sid) for c in range(args.channels)]
    for win in windows(args.messages, args.channels, args.window):
        t0 = perf_counter()
        times = np.concatenate([t for t, _ in win])
        data = [d for _, ds in win for d in ds]
        chans = np.repeat(ids, [len(t) for t, _ in win])
        for i in np.argsort(times, kind="stable").tolist():
            ti = int(times[i])
            w.add_message(int(chans[i]), log_time=ti, data=data[i], publish_time=ti)
        spent += perf_counter() - t0
    t0 = perf_counter()
    w.finish()
    fh.close()
    return spent + perf_counter() - t0


def child(args) -> None:
    path = Path(args.child_path)
    spent = (run_bulk if args.child == "bulk" else run_library)(path, args)
    print(json.dumps({"seconds": spent}))


def messages_of(path: Path) -> tuple[int, int]:
    """(count, hash of the (channel topic, log time, data) sequence) read back with mcap's reader."""
    from mcap.reader import make_reader

    h, n = 0, 0
    with open(path, "rb") as fh:
        for _, ch, m in make_reader(fh).iter_messages(log_time_order=True):
            h = hash((h, ch.topic, m.log_time, m.data))
            n += 1
    return n, h


def measure(kind: str, n: int, args, work: Path) -> dict:
    path = work / f"{kind}-{n}.mcap"
    cmd = [sys.executable, __file__, "--child", kind, "--child-path", str(path), "--messages", str(n),
           "--channels", str(args.channels), "--window", str(args.window), "--compression", args.compression]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    if status:
        raise SystemExit(f"{kind} {n}: the child failed")
    return {"seconds": json.loads(out)["seconds"], "rss_mb": usage.ru_maxrss / 1024, "size_mb": path.stat().st_size / 1e6,
            "path": path}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--messages", default="200000,1000000")
    ap.add_argument("--channels", type=int, default=8)
    ap.add_argument("--window", type=int, default=1 << 16)
    ap.add_argument("--compression", default="zstd", choices=["zstd", "lz4", ""])
    ap.add_argument("--child", choices=["bulk", "library"])
    ap.add_argument("--child-path")
    args = ap.parse_args()
    if args.child:
        args.messages = int(args.messages)
        return child(args)
    print(f"{'messages':>9} {'writer':>8} {'s':>7} {'us/msg':>7} {'peak RSS MB':>12} {'file MB':>8}  same messages")
    with tempfile.TemporaryDirectory() as tmp:
        for n in [int(x) for x in args.messages.split(",")]:
            rows = {k: measure(k, n, args, Path(tmp)) for k in ("bulk", "library")}
            same = messages_of(rows["bulk"]["path"]) == messages_of(rows["library"]["path"])
            for k, r in rows.items():
                print(f"{n:>9} {k:>8} {r['seconds']:7.2f} {1e6 * r['seconds'] / n:7.2f} {r['rss_mb']:12.0f} "
                      f"{r['size_mb']:8.1f}  {same}")


if __name__ == "__main__":
    main()
