"""``replay reproduce 000``: GPF vs MMPF vs EKF on synthetic lake-trial logs (paper 000).

The paper's lake-trial data are not published, so every run uses a fresh
``sim/lake-depth`` log (SYNTHETIC: same maneuvering profile, new sensor noise
from the run's seed) under the ``depth`` task with the paper's parameters:
T = 0.05 s, N = 1000, N_grey = 100, L = 30, wavelet window 50, db6; Q = the
fallback diag(0.2^2, 1^2, 0.5^2) (the printed Q is not positive definite);
EKF and MMPF with R = diag(0.2^2, 5^2, 0.5^2).

Reported per channel (depth, speed, pitch): mean over runs of the per-run
RMSE with its 95 % interval, the same inside and outside the maneuver
segments, and paired differences (common random numbers: every filter sees the
same measurements in a run). The paper's claims are checked:

* "GPF < MMPF < EKF": confirmed when both paired differences are negative with
  95 % intervals below zero; refuted when an interval lies wholly above zero;
  otherwise inconclusive;
* "EKF worst during maneuvers": EKF's maneuver-segment RMSE is the largest of
  the three (paired intervals), and its maneuver/level ratio the largest.

Ablation: GPF without grey particles (``grey=False``) and without wavelet noise
estimation (``wavelet=False``, fixed R). The raw sensor's RMSE is given as a
yardstick.

Sensitivity (:data:`READINGS`): the paper prints Q and R without units. The
primary table reads them in SI units (pitch in rad). Two more readings run
GPF, MMPF and EKF on the same runs (same data seeds):

* ``degrees``: the pitch rows/columns of Q and of the fixed R in degrees
  (Q' = S Q S, R' = S R S, S = diag(1, 1, pi/180): pitch noise 0.5 deg per step,
  pitch sensor 0.5 deg); the generator unchanged (its pitch sensor's base noise
  is already 0.5 deg; depth and speed sensors far below R's 0.2 m and 5 m/s);
* ``degrees, sensors at R``: as ``degrees``, and the generator's sensor noise
  scaled (:func:`replay.sim.lake_depth.base_for_rms`) so that its RMS over the
  run equals the fixed R's std per channel (0.2 m, 5 m/s, 0.5 deg), the
  regimes and drift varying around it: the EKF's R is then right on average,
  the premise of the paper's argument that a fixed R fails when the noise
  varies. A speed noise of 5 m/s on a 1.2-2 m/s vehicle is implausible for a
  real log; it is what the printed R says.

The printed Q is not positive definite under any of these readings (its
depth-speed entry 0.8^2 exceeds sqrt(0.2^2 * 1^2)), so the diagonal fallback is
converted. Every run goes through the pipeline of ``replay eval``
(:func:`replay.pipeline.run_block`), with its seeds: (seed, run, 0) data,
(seed, run, 1) task, (seed, run, 2, crc32(filter name)) filter — the ablation
variants of the GPF share the GPF's stream (common random numbers).
"""
from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from replay import score
from replay.models.depth import R_FIXED, paper_Q
from replay.pipeline import Config, run_block
from replay.sim.lake_depth import base_for_rms

VARIANTS = {  # label -> (filter, params)
    "GPF": ("gpf", {}),
    "MMPF": ("mmpf", {}),
    "EKF": ("ekf", {}),
    "GPF without grey particles": ("gpf", {"grey": False}),
    "GPF without wavelet noise": ("gpf", {"wavelet": False}),
}
MAIN = ("GPF", "MMPF", "EKF")
CHANNELS = (("depth", 0, "m"), ("speed", 1, "m/s"), ("pitch", 2, "rad"))
DATASET = "sim/lake-depth"
PRIMARY = "as printed"
S_DEG = np.diag([1.0, 1.0, np.pi / 180.0])  # pitch rows/columns of Q and R read in degrees


def _readings():
    """reading -> (DepthTask options, generator options, what it means)."""
    Qd, Rd = S_DEG @ paper_Q()[0] @ S_DEG, S_DEG @ R_FIXED @ S_DEG
    return {
        PRIMARY: ({}, {}, "SI units as printed: Q = diag(0.2², 1², 0.5²) (m², (m/s)², rad²), "
                  "R = diag(0.2², 5², 0.5²) (m², (m/s)², rad²); `sim/lake-depth` sensors as generated"),
        "degrees": ({"Q": Qd.tolist(), "R": Rd.tolist()}, {}, "pitch entries in degrees: Q = diag(0.2², 1², (0.5°)²), "
                    "R = diag(0.2², 5², (0.5°)²); sensors as generated (RMS over the run ≈ 0.12 m, 0.12 m/s, "
                    "1.2°: depth and speed below R, pitch 2.4 × R's 0.5°)"),
        "degrees, sensors at R": ({"Q": Qd.tolist(), "R": Rd.tolist()},
                                  {"base_sigma": [float(v) for v in base_for_rms(np.sqrt(np.diag(Rd)))]},
                                  "Q and R as in `degrees`; sensor noise scaled so that its RMS over the run "
                                  "is R's std (0.2 m, 5 m/s, 0.5°), regimes and drift around it"),
    }


READINGS = _readings()


def config(reading: str, name: str, params: dict, seed: int) -> Config:
    """The pipeline configuration of one variant under one reading (:mod:`replay.pipeline`)."""
    task_opts, gen_opts, _ = READINGS[reading]
    return Config(DATASET, gen_opts, None, "depth", task_opts, name, params, seed)


def one_run(args):
    """Errors (n, 3) of every variant and of the raw sensor for one Monte Carlo run of a reading,
    computed by the pipeline of ``replay eval`` (:func:`replay.pipeline.run_block`)."""
    seed, run, reading = args
    variants = VARIANTS if reading == PRIMARY else {k: VARIANTS[k] for k in MAIN}
    out, problem = {}, None
    for label, (name, params) in variants.items():
        rec = run_block(config(reading, name, params, seed), [run], keep=True, strict=True)[0]
        err, problem = rec["errors"], rec["problem"]
        e = np.column_stack([err["position"][:, 0], err["speed"], err["pitch"]])
        out[label] = (e, rec["estimates"].us_per_step)
    truth = np.column_stack([problem.truth_position[:, 0], problem.truth_extra["speed"][0],
                             problem.truth_angles["pitch"]])
    e = problem.z - truth
    e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
    out["sensor"] = (e, np.nan)
    meta = problem.frame_meta
    return out, problem.t, meta["maneuvers"], reading


def _mean_ci(values):
    v = np.asarray(values, float)
    return float(np.nanmean(v)), score.ci95(v)


def _rmse(e, sel):
    return np.sqrt(np.nanmean(e[sel] ** 2, axis=0))


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False):
    runs = runs or (4 if quick else 100)
    doc = Path(doc) if doc else Path("docs/reproduction/000.md")
    t0 = time.perf_counter()
    workers = max(1, min(int(os.environ.get("REPLAY_WORKERS", 2)), runs))
    jobs = [(seed, r, reading) for reading in READINGS for r in range(runs)]
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            results = list(pool.map(one_run, jobs))
    else:
        results = [one_run(j) for j in jobs]
    t, segments = results[0][1], results[0][2]
    man = np.zeros(len(t), bool)
    for a, b, _ in segments:
        man |= (t >= a) & (t < b)
    per, curves = {}, None
    for reading in READINGS:
        mine = [r[0] for r in results if r[3] == reading]
        per[reading], c = _summarise(mine, man, keep_curves=reading == PRIMARY)
        curves = c if reading == PRIMARY else curves
    elapsed = time.perf_counter() - t0
    png = doc.with_name(doc.stem + "_rmse.png")
    doc.parent.mkdir(parents=True, exist_ok=True)
    _plot(png, t, curves, segments)
    text = _report(per, runs, seed, segments, elapsed, png.name, workers)
    doc.write_text(text)
    print(text)
    print(f"wrote {doc} and {png}")
    return per


def _summarise(results, man, keep_curves=False):
    """Per-run RMSE (runs, 3) over all / maneuver / level samples for every label, and the errors."""
    labels = list(results[0])
    per = {lab: {"all": [], "man": [], "level": [], "us": []} for lab in labels}
    curves = {lab: [] for lab in labels} if keep_curves else None
    for res in results:
        for lab in labels:
            e, us = res[lab]
            per[lab]["all"].append(_rmse(e, slice(None)))
            per[lab]["man"].append(_rmse(e, man))
            per[lab]["level"].append(_rmse(e, ~man))
            per[lab]["us"].append(us)
            if keep_curves:
                curves[lab].append(e)
    for lab in labels:
        for k in ("all", "man", "level"):
            per[lab][k] = np.array(per[lab][k])  # (runs, 3)
    return per, curves


def _verdict(diff):
    """Claim 'a < b' from paired per-run differences a - b."""
    m, c = _mean_ci(diff)
    if m + c < 0:
        return "confirmed", m, c
    if m - c > 0:
        return "refuted", m, c
    return "inconclusive", m, c


def _claims(per, j):
    """The paper's claims on channel j: paired verdicts and the maneuver/level ratios."""
    v1, m1, c1 = _verdict(per["GPF"]["all"][:, j] - per["MMPF"]["all"][:, j])
    v2, m2, c2 = _verdict(per["MMPF"]["all"][:, j] - per["EKF"]["all"][:, j])
    both = "confirmed" if v1 == v2 == "confirmed" else ("refuted" if "refuted" in (v1, v2) else "inconclusive")
    worst = [_verdict(per[o]["man"][:, j] - per["EKF"]["man"][:, j])[0] for o in ("GPF", "MMPF")]
    ekf_worst = "confirmed" if worst == ["confirmed"] * 2 else (
        "refuted" if "refuted" in worst else "inconclusive")
    ratio = {lab: np.nanmean(per[lab]["man"][:, j]) / np.nanmean(per[lab]["level"][:, j]) for lab in MAIN}
    degr = "yes" if max(ratio, key=ratio.get) == "EKF" else "no"
    rtxt = ", ".join(f"{k} {v:.2f}" for k, v in ratio.items())
    return {"gm": (v1, m1, c1), "me": (v2, m2, c2), "both": both, "ekf_worst": ekf_worst,
            "degrades": f"{degr} ({rtxt})"}


def _rmse_table(per, labels, us=True):
    L = ["| filter | depth (m) | speed (m/s) | pitch (rad) |" + (" µs/step |" if us else ""),
         "|---|---|---|---|" + ("---|" if us else "")]
    for lab in labels:
        cells = []
        for j in range(3):
            m, c = _mean_ci(per[lab]["all"][:, j])
            cells.append(f"{m:.4f} ± {c:.4f}")
        name = "raw sensor (yardstick)" if lab == "sensor" else lab
        row = f"| {name} | " + " | ".join(cells) + " |"
        if us:
            row += " |" if lab == "sensor" else f" {np.nanmedian(per[lab]['us']):.0f} |"
        L.append(row)
    return L


def _claims_table(per):
    L = ["| channel | GPF − MMPF | GPF < MMPF | MMPF − EKF | MMPF < EKF | GPF < MMPF < EKF | "
         "EKF worst in maneuvers | EKF degrades most (man./level) |", "|---|---|---|---|---|---|---|---|"]
    for j, (ch, _, unit) in enumerate(CHANNELS):
        c = _claims(per, j)
        (v1, m1, c1), (v2, m2, c2) = c["gm"], c["me"]
        L.append(f"| {ch} ({unit}) | {m1:+.4f} ± {c1:.4f} | {v1} | {m2:+.4f} ± {c2:.4f} | {v2} | "
                 f"**{c['both']}** | {c['ekf_worst']} | {c['degrades']} |")
    return L


def _report(per_all, runs, seed, segments, elapsed, png, workers=2):
    per = per_all[PRIMARY]
    L = ["# Paper 000 — grey particle filter (GPF) for maneuvering-AUV depth: reproduction", "",
         "Generated by `replay reproduce 000"
         + (f" --runs {runs}" if runs != 100 else "") + (f" --seed {seed}" if seed else "") + "`"
         f" ({runs} Monte Carlo runs per reading, {len(per_all)} readings, {elapsed:.0f} s with "
         f"{workers} worker processes). **Data: SYNTHETIC** lake-trial logs from "
         "`sim/lake-depth` (the paper's lake trial is not published): one fixed maneuvering profile, "
         "new sensor noise every run, noise std changing over time (regimes ×1, ×3, ×0.5, ×2 over the "
         "quarters of the run, times a slow drift 1 → 1.5); the true trajectory is the external reference.",
         "", "Parameters as printed (§3): T = 0.05 s, N = 1000, N_grey = 100, grey window L = 30, wavelet "
         "window 50, M = 5, db6; EKF and MMPF with R = diag(0.2², 5², 0.5²). **Q**: the printed matrix "
         "[[0.2², 0.8², 0.6²], [0.8², 1², 0], [0.6², 0, 0.5²]] is not positive definite (determinant "
         "−0.22), so Q = diag(0.2², 1², 0.5²) is used, as the digest prescribes. The primary tables read "
         "the printed numbers in SI units (m, m/s, rad); the paper does not state them (0.5 rad of pitch "
         "noise per 0.05 s step is very large): see the sensitivity section for the degree readings. "
         "MMPF: three modes (steady, pitch rate ±10°/s), stay probability 0.95 (`filters/p000/mmpf.py`).", "",
         "Maneuver segments (non-zero pitch command, +1.5 s settling): "
         + ", ".join(f"{a:g}–{b:g} s {lab}" for a, b, lab in segments) + ".", "",
         "## RMSE, mean over runs (± 95 % interval)", "", *_rmse_table(per, ["sensor", *VARIANTS]),
         "", "## During maneuvers and level runs", "",
         "| filter | depth man. | depth level | speed man. | speed level | pitch man. | pitch level |",
         "|---|---|---|---|---|---|---|"]
    for lab in ["sensor", *MAIN]:
        cells = []
        for j in range(3):
            for k in ("man", "level"):
                m, c = _mean_ci(per[lab][k][:, j])
                cells.append(f"{m:.4f} ± {c:.4f}")
        L.append(f"| {lab} | " + " | ".join(cells) + " |")
    L += ["", "## The paper's claims, per channel", "",
          "Paired differences of per-run RMSE (mean ± 95 % interval).", "", *_claims_table(per)]
    L += ["", "## Ablation: which part of GPF does the work", "",
          "| variant | depth | speed | pitch |", "|---|---|---|---|"]
    for lab in ("GPF", "GPF without grey particles", "GPF without wavelet noise"):
        cells = []
        for j in range(3):
            d = per[lab]["all"][:, j] - per["GPF"]["all"][:, j]
            m, c = _mean_ci(d)
            base = np.nanmean(per[lab]["all"][:, j])
            cells.append(f"{base:.4f}" + ("" if lab == "GPF" else f" (vs GPF {m:+.4f} ± {c:.4f})"))
        L.append(f"| {lab} | " + " | ".join(cells) + " |")
    L += ["", f"![RMSE across runs at each time step, maneuvers shaded]({png})", ""]
    L += _sensitivity(per_all)
    L += ["", "## Reading", "",
          "The verdicts above are computed, not written by hand; see the tables. What drives the primary "
          "(SI) verdicts: with the paper's Q read in SI units (speed random walk of 1 m/s and pitch of "
          "0.5 rad per 0.05 s step) every particle filter spreads its particles far wider than the sensor "
          "noise, so after weighting the PFs track the measurements about as closely as the likelihood "
          "width lets them (GPF: the wavelet-estimated, small sensor noise; MMPF: the fixed R), and their "
          "speed estimate carries a Monte Carlo error of the order of the posterior spread (≈ 2 m/s) over "
          "√N. The EKF, with the large fixed R, averages over many samples, which on this smooth trajectory "
          "beats following the measurements. The sensitivity readings change the pitch noise scales and "
          "the sensors' level; their verdicts are in the summary table above. In the `degrees` reading the "
          "pitch R (0.5°) is below the generator's pitch noise (RMS 1.2°, up to 2.25° in the ×3 regime), so "
          "in the noisy regimes the pitch likelihood is sharp and off-centre and the PFs' effective sample "
          "size falls (bootstrap PF with the fixed R, run 0: median ESS 100–200 of 1000 there, ≈ 550 "
          "elsewhere); their speed estimate, whose particle spread is ≈ 2 m/s (Q_vv = 1 per step against "
          "R_vv = 25), then picks up a large Monte Carlo error that the EKF does not have. With the sensors "
          "at R, the EKF's R is right on average and the three filters come much closer together. Whether "
          "the paper's ordering would appear with its real lake-trial data (and its unstated units) cannot "
          "be checked.",
          "", "Checks that the filters are not the cause: on a near-linear depth model with small known Q "
          "and R, the bootstrap PF inside GPF (no grey particles, fixed R), a one-mode MMPF and GPF with "
          "wavelet R all agree with the EKF to a fraction of its error (`tests/test_gpf.py::"
          "test_particle_filters_agree_with_ekf_on_a_near_linear_model`).",
          "", "Reproduce: `replay reproduce 000` (100 runs per reading; `--quick` for a 4-run smoke check; "
          "`REPLAY_WORKERS` sets the worker processes, default 2).", ""]
    return "\n".join(L)


def _sensitivity(per_all):
    L = ["## Sensitivity: units of Q and R, and the sensors' noise level", "",
         "The paper prints Q and R without units. Each reading runs GPF, MMPF and EKF on the same Monte "
         "Carlo runs (same data seeds: common random numbers; a reading that rescales the sensors scales "
         "the same draws). The printed Q stays not positive definite under every reading (its depth–speed "
         "entry 0.8² exceeds √(0.2² · 1²)), so the diagonal fallback is converted: Q′ = S Q S, "
         "R′ = S R S with S = diag(1, 1, π/180).", "",
         "| reading | Q, R and sensors | why |", "|---|---|---|",
         f"| {PRIMARY} (primary) | {READINGS[PRIMARY][2]} | the print taken literally; a 29° pitch noise "
         "(0.5 rad) per step and a 5 m/s speed-sensor std are implausible for an AUV |",
         f"| degrees | {READINGS['degrees'][2]} | 0.5° is a plausible pitch-sensor noise and a plausible "
         "per-step pitch disturbance; the likeliest reading of the pitch entries |",
         f"| degrees, sensors at R | {READINGS['degrees, sensors at R'][2]} | the baselines' fixed R "
         "describes the sensors on average, as an experimenter would set it; the noise varies around it, "
         "which is the case the paper argues GPF's wavelet R is for. Faithful for depth and pitch; for "
         "speed it takes the printed 5 m/s literally (implausible for a real speed log) |", "",
         "### Summary: does the claim hold? (paired 95 % intervals)", "",
         "| reading | depth: GPF < MMPF < EKF | speed | pitch | EKF worst in maneuvers (depth / speed / pitch) |",
         "|---|---|---|---|---|"]
    for reading, per in per_all.items():
        c = [_claims(per, j) for j in range(3)]
        L.append(f"| {reading} | " + " | ".join(x["both"] for x in c) + " | "
                 + " / ".join(x["ekf_worst"] for x in c) + " |")
    for reading, per in per_all.items():
        if reading == PRIMARY:
            continue
        L += ["", f"### Reading: {reading}", "", *_rmse_table(per, ["sensor", *MAIN], us=False), "",
              *_claims_table(per)]
    return L


def _plot(path, t, curves, segments):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    styles = {"GPF": "C0-", "MMPF": "C1-", "EKF": "C2-", "GPF without grey particles": "C0:",
              "GPF without wavelet noise": "C0--", "sensor": "k-"}
    for j, (ch, _, unit) in enumerate(CHANNELS):
        ax = axes[j]
        for a, b, _ in segments:
            ax.axvspan(a, b, color="0.9")
        for lab, style in styles.items():
            e = np.stack(curves[lab])[:, :, j]
            with np.errstate(invalid="ignore"):
                r = np.sqrt(np.nanmean(e**2, axis=0))
            ax.plot(t, r, style, lw=0.8 if lab == "sensor" else 1.2, alpha=0.5 if lab == "sensor" else 1,
                    label="raw sensor" if lab == "sensor" else lab)
        ax.set_ylabel(f"{ch} RMSE ({unit})")
        ax.set_yscale("log")
    axes[0].legend(fontsize=7, ncol=3)
    axes[-1].set_xlabel("time (s); grey: maneuver segments")
    fig.suptitle("Paper 000 on synthetic lake-trial logs: RMSE across Monte Carlo runs")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
