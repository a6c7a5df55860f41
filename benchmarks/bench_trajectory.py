"""Trajectory scoring speed: APE + RPE with SE(3) alignment on 100k poses, ours against evo.

One run of each, same data, same settings: nearest-time association, SE(3) Umeyama alignment,
APE and RPE (delta 1 frame, consecutive pairs) for the translation and the rotation-angle
(degrees) relations. evo is run as its CLI does it (one call per metric and relation:
``evo_ape -a -r trans_part``, ``-r angle_deg``, ``evo_rpe`` likewise); ours both that way and
in one call computing every relation. The statistics are compared too (they must agree to 1e-6
relative). Target: ours >= 20x faster; reported, never asserted.

    .venv/bin/python benchmarks/bench_trajectory.py [--poses 100000] [--skip-evo]

evo is a GPL test/benchmark oracle (``pip install evo``), never imported by the library. With
100k poses evo needs several minutes (about 1 ms per pose and rotation relation).
"""
from __future__ import annotations

import argparse
import copy
import tempfile
from pathlib import Path
from time import perf_counter

import numpy as np
from scipy.spatial.transform import Rotation

from replay.trajectory import load, pose_error, score
from replay.trajectory.base import make
from replay.trajectory.files import write_tum

RELATIONS = ("trans", "angle_deg")


def data(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    t = 1.7e9 + np.arange(n) * 0.02
    s = np.arange(n) * 0.02
    p = np.column_stack([200 * np.sin(s / 300), 150 * np.sin(s / 170), 10 * np.sin(s / 60)])
    q = Rotation.from_euler("xyz", np.column_stack([0.1 * np.sin(s / 7), 0.1 * np.cos(s / 9), s / 50])).as_quat()
    ref = make(t, p, q, source="reference")
    R = Rotation.from_euler("zyx", [0.4, 0.02, -0.01]).as_matrix()
    pe = (p + np.cumsum(rng.normal(0, 0.01, (n, 3)), axis=0)) @ R.T + [3, -2, 1]
    qe = (Rotation.from_matrix(R) * Rotation.from_quat(q) * Rotation.from_rotvec(rng.normal(0, 0.005, (n, 3))))
    est = make(t + rng.uniform(-0.002, 0.002, n), pe, qe.as_quat(), source="estimate")
    return ref, est


def ours(ref, est, separate: bool) -> tuple[float, dict]:
    t0 = perf_counter()
    stats = {}
    calls = [[r] for r in RELATIONS] if separate else [list(RELATIONS)]
    for rels in calls:
        a = score(ref, est, align="se3", relations=rels)  # APE (as evo_ape)
        b = score(ref, est, align="se3", relations=rels, delta=1, delta_unit="f")  # RPE (as evo_rpe)
        for r in rels:
            stats[("ape", r)] = pose_error.statistics(a.ape[r])
            stats[("rpe", r)] = pose_error.statistics(b.rpe[r])
    return perf_counter() - t0, stats


def evo_run(ref, est) -> tuple[float, dict]:
    from evo.core import metrics, sync
    from evo.core.trajectory import PoseTrajectory3D
    from evo.main_ape import ape
    from evo.main_rpe import rpe

    rel = {"trans": metrics.PoseRelation.translation_part, "angle_deg": metrics.PoseRelation.rotation_angle_deg}
    r0 = PoseTrajectory3D(ref.p, np.roll(ref.q, 1, axis=1), ref.t)
    e0 = PoseTrajectory3D(est.p, np.roll(est.q, 1, axis=1), est.t)
    t0 = perf_counter()
    stats = {}
    for r in RELATIONS:
        for kind in ("ape", "rpe"):
            a, b = sync.associate_trajectories(copy.deepcopy(r0), copy.deepcopy(e0), max_diff=0.01)
            if kind == "ape":
                res = ape(a, b, rel[r], align=True)
            else:
                res = rpe(a, b, rel[r], delta=1, delta_unit=metrics.Unit.frames, align=True)
            stats[(kind, r)] = res.stats
    return perf_counter() - t0, stats


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=100_000)
    ap.add_argument("--skip-evo", action="store_true", help="time ours only")
    args = ap.parse_args()
    ref, est = data(args.poses)
    with tempfile.TemporaryDirectory() as tmp:
        write_tum(Path(tmp) / "ref.tum", ref)
        t0 = perf_counter()
        load(str(Path(tmp) / "ref.tum"))
        print(f"read a TUM file of {args.poses} poses: {perf_counter() - t0:.3f} s (not in the timings below)")
    t_sep, s_ours = ours(ref, est, separate=True)
    t_one, _ = ours(ref, est, separate=False)
    print(f"ours, one call per metric and relation (as evo): {t_sep:.3f} s")
    print(f"ours, one call per metric, both relations:       {t_one:.3f} s")
    if args.skip_evo:
        return
    try:
        import evo  # noqa: F401
    except ImportError:
        print("evo is not installed: pip install evo (the oracle) to compare")
        return
    print(f"evo {evo.__version__}: running (several minutes for 100k poses) ...", flush=True)
    t_evo, s_evo = evo_run(ref, est)
    print(f"evo, APE + RPE, trans + angle_deg, SE(3): {t_evo:.1f} s")
    worst = max(abs(s_ours[k][m] - float(s_evo[k][m])) / max(abs(float(s_evo[k][m])), 1e-300)
                for k in s_ours for m in pose_error.STATISTICS)
    print(f"statistics agree: largest relative difference {worst:.2e} (must be < 1e-6)")
    print(f"speed-up: {t_evo / t_sep:.0f}x (as evo, one call per relation), {t_evo / t_one:.0f}x (one call); "
          f"target >= 20x: {'PASS' if t_evo / t_sep >= 20 else 'MISS'}")


if __name__ == "__main__":
    main()
