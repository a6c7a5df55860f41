"""Peak memory and time of `replay export` against the number of messages.

    .venv/bin/python benchmarks/bench_export_memory.py [--sizes 10000,50000,150000] [--ros2]
                     [--keep DIR] [--work DIR]

For each size N it builds a synthetic run directory (no filter is run): a Bohai-layout
CSV of N samples at 10 Hz (a smooth survey track near 40.6 N 121.0 E, a GPS fix every
10 samples), a manifest taken from a real `replay eval` of that CSV over its first 100
samples (config edited to all N samples and four filters: ekf, ukf, ckf, pf) and
synthetic estimates of N steps for each filter. It then runs `replay export RUN --mcap`
(and `--ros2-bag` with ``--ros2``) in a fresh process and reads that process's own peak
resident set (``os.wait4`` rusage, ``ru_maxrss``) and wall time. The table gives
messages written, file size, peak RSS, RSS above a bare interpreter that imported the
same modules (``base``), bytes per message of that excess, wall time, and the sha256 of
the MCAP (so that two versions of the code can be compared byte for byte). Nothing is
asserted: it is a report. The issue's target: peak RSS under 400 MB for a 150k-sample,
4-filter export, time at most 1.5x that of the whole-file writer.
"""
from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from time import perf_counter

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FILTERS = ("ekf", "ukf", "ckf", "pf")
COLUMNS = ("lat_gps,lon_gps,alt_gps,roll,pitch,yaw,vn,ve,vf,vl,vu,ax,ay,az,af,al,au,wx,wy,wz,wf,wl,wu,"
           "pos_accuracy,vel_accuracy,navstat,numsats,posmode,velmode,orimode,lat,lon,depth,height,time,"
           "time_gps").split(",")


def replay_cmd() -> list[str]:
    exe = Path(sys.executable).with_name("replay")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "replay.cli"]


def track(n: int, rng):
    """East, north (m) and yaw (rad) of a smooth 2 m/s survey track, 10 Hz."""
    t = np.arange(n) * 0.1
    yaw = 0.3 * np.sin(t / 200.0)
    east, north = np.cumsum(2.0 * np.cos(yaw) * 0.1), np.cumsum(2.0 * np.sin(yaw) * 0.1)
    return t, east, north, yaw


def write_csv(path: Path, n: int) -> None:
    """A Bohai-layout (36-column) CSV of n samples; numsats..orimode repeat time as upstream."""
    rng = np.random.default_rng(0)
    t, east, north, yaw = track(n, rng)
    lat = 40.6 + north / 111_000.0
    lon = 121.0 + east / (111_000.0 * np.cos(np.radians(40.6)))
    fix = (np.arange(n) // 10) * 10
    zero = np.zeros(n)
    cols = {c: zero for c in COLUMNS}
    cols.update(lat_gps=lat[fix] + rng.normal(0, 1e-5, n)[fix], lon_gps=lon[fix] + rng.normal(0, 1e-5, n)[fix],
                alt_gps=zero + 1.0, roll=rng.normal(0, 0.01, n), pitch=rng.normal(0, 0.01, n), yaw=yaw,
                vn=2.0 * np.sin(yaw), ve=2.0 * np.cos(yaw), vf=zero + 2.0, wz=np.gradient(yaw, t), navstat=zero + 1,
                numsats=t, posmode=t, velmode=t, orimode=t, lat=lat, lon=lon, time=t, time_gps=t[fix])
    with open(path, "w") as fh:
        fh.write(",".join(COLUMNS) + "\n")
        np.savetxt(fh, np.column_stack([cols[c] for c in COLUMNS]), delimiter=",", fmt="%.10g")


def make_run(work: Path, n: int) -> Path:
    """A `replay eval` output directory for n samples and four filters, estimates synthetic."""
    csv = work / f"survey_{n}.csv"
    write_csv(csv, n)
    run = work / f"run_{n}"
    res = subprocess.run([*replay_cmd(), "eval", str(csv), "-f", "ekf", "--first", "100", "-o", str(run)],
                         capture_output=True, text=True)
    if res.returncode:
        raise SystemExit(f"replay eval failed:\n{res.stderr}")
    man = json.loads((run / "manifest.json").read_text())
    man["config"].update(filters=list(FILTERS), first=None)
    (run / "manifest.json").write_text(json.dumps(man, indent=2))
    rng = np.random.default_rng(1)
    t, east, north, _ = track(n, rng)
    head = "run,k,t,x0,x1,x2,P00,P11,P22,err_x,err_y,err_z\n"
    for name in FILTERS:
        err = rng.normal(0, 1.5, (n, 3))
        x = np.column_stack([east - east[0], north - north[0], np.zeros(n)]) + err
        block = np.column_stack([np.zeros(n), np.arange(n), t, x, np.full((n, 3), 0.7), err])
        with gzip.open(run / "estimates" / f"{name}.csv.gz", "wt", newline="") as fh:
            fh.write(head)
            np.savetxt(fh, block, delimiter=",", fmt="%.10g")
    return run


def measure(args: list[str]) -> tuple[float, float, str]:
    """(peak RSS in MB, wall seconds, stdout) of one command in a fresh process (its own rusage, os.wait4)."""
    t0 = perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = perf_counter() - t0
    if proc.returncode:
        raise SystemExit(f"{' '.join(args)} failed (exit {proc.returncode})")
    return usage.ru_maxrss / 1024, wall, out


def baseline_rss() -> float:
    """Peak RSS of an interpreter that only imports what an export imports (MB)."""
    code = ("import replay.outputs.export_mcap, replay.outputs.export_ros2, replay.adapters.bohai, "
            "replay.tasks, mcap.writer, foxglove_schemas_protobuf.PoseInFrame_pb2, zstandard, rosbags.rosbag2")
    return measure([sys.executable, "-c", code])[0]


def sha256(path: Path) -> str:
    if path.is_dir():
        path = next(path.glob("*.mcap"))
    return hashlib.sha256(path.read_bytes()).hexdigest()


def size_of(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*")) if path.is_dir() else path.stat().st_size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="10000,50000,150000", help="samples per run, comma-separated")
    ap.add_argument("--ros2", action="store_true", help="also time the ROS 2 bag export")
    ap.add_argument("--keep", default=None, help="copy the exported files into this directory")
    ap.add_argument("--work", default=None, help="build the run directories here (reused if present)")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",") if s]
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="bench_export_"))
    work.mkdir(parents=True, exist_ok=True)
    base = baseline_rss()
    print(f"base (imports only): {base:.0f} MB peak RSS; python {sys.version.split()[0]}, numpy {np.__version__}")
    head = f"{'kind':5} {'samples':>8} {'messages':>10} {'MB file':>8} {'peak MB':>8} {'excess MB':>9} " \
           f"{'B/msg':>6} {'wall s':>7}  sha256"
    print(head)
    try:
        for n in sizes:
            run = work / f"run_{n}"
            if not (run / "manifest.json").is_file():
                make_run(work, n)
            kinds = [("mcap", "--mcap", work / f"out_{n}.mcap")]
            if args.ros2:
                kinds.append(("ros2", "--ros2-bag", work / f"out_{n}_ros2"))
            for kind, flag, out in kinds:
                if out.is_dir():
                    shutil.rmtree(out)
                elif out.exists():
                    out.unlink()
                peak, wall, text = measure([*replay_cmd(), "export", str(run), flag, str(out)])
                msgs = int(text.rsplit("(", 1)[1].split()[0])
                excess = max(peak - base, 0.0)
                print(f"{kind:5} {n:8d} {msgs:10d} {size_of(out) / 1e6:8.1f} {peak:8.0f} {excess:9.0f} "
                      f"{excess * 2**20 / msgs:6.0f} {wall:7.2f}  {sha256(out)[:16]}", flush=True)
                if args.keep:
                    keep = Path(args.keep)
                    keep.mkdir(parents=True, exist_ok=True)
                    dst = keep / out.name
                    if out.is_dir():
                        shutil.rmtree(dst, ignore_errors=True)
                        shutil.copytree(out, dst)
                    else:
                        shutil.copy2(out, dst)
    finally:
        if not args.work:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
