"""The evidence tables and the figure of ``docs/reproduction/000.md`` (:mod:`replay.reproduce.p000`).

``results[cell][label]``: a filter's data from :func:`replay.reproduce.p000_cells.compute`;
``commands[cell]``: the ``replay eval`` commands that computed the cell.
"""
from __future__ import annotations

import numpy as np

from .p000_cells import ABLATIONS, CHANNELS, MAIN, fmt, paired, status
from .p000_claims import OTHERS, SECTIONS, advantage, ekf_degrades_most, ekf_worst, ordering, ratios
from .verdict import cell as md, result_rows

CH = [c for c, _ in CHANNELS]


def _mean(v) -> str:
    v = np.asarray(v, float)
    return fmt(float(np.nanmean(v))) if np.isfinite(v).any() else "n/a"


def grid_table(results, cells) -> list[str]:
    L = [f"## {SECTIONS['grid']}", "",
         "Per cell and channel: paired GPF − MMPF / MMPF − EKF (per-run RMSE, mean ± 95 % interval; m, m/s, "
         "rad) and whether **GPF < MMPF < EKF** holds (both intervals below 0), fails (one above 0) or is "
         "unresolved.", "", "| sensors | κ | depth | speed | pitch | all three |", "|---|---|---|---|---|---|"]
    for c in cells:
        cells_ch, sts = [], []
        for ch in CH:
            d1, d2, st = ordering(results[c], ch)
            sts.append(st)
            cells_ch.append(f"{fmt(*d1, sign=True)} / {fmt(*d2, sign=True)} {st}")
        allst = "**holds**" if all(s == "holds" for s in sts) else ("fails" if "fails" in sts else "unresolved")
        L.append(f"| {c.noise_text} | {c.kappa:g} | " + " | ".join(cells_ch) + f" | {allst} |")
    return L + [""]


def tuned_table(results, grid) -> list[str]:
    """Each filter at the kappa that suits it best (per sensor level and channel), and GPF against
    the best of them (paired: the cells of one sensor level share their measurements)."""
    L = [f"## {SECTIONS['tuned']}", "",
         "A referee's question: is GPF ahead only because the baselines got a bad Q? For each sensor level "
         "and channel, every filter's mean RMSE at the κ of the sweep that suits it best (κ in brackets), and "
         "GPF at its best κ minus the best filter at its best κ (paired over the same runs).", "",
         "| sensors | channel | " + " | ".join(MAIN) + " | GPF (best) − best other (best) |",
         "|---|---|" + "---|" * (len(MAIN) + 1)]
    for noise in dict.fromkeys(c.noise for c in grid):
        cs = [c for c in grid if c.noise == noise]
        for ch in CH:
            best = {lab: min(cs, key=lambda c: np.nanmean(results[c][lab]["rmse"][ch])) for lab in MAIN}
            row = [f"{_mean(results[best[lab]][lab]['rmse'][ch])} ({best[lab].kappa:g})" for lab in MAIN]
            other = min(OTHERS, key=lambda lab: np.nanmean(results[best[lab]][lab]["rmse"][ch]))
            d = paired(results[best["GPF"]]["GPF"]["rmse"][ch], results[best[other]][other]["rmse"][ch])
            L.append(f"| {cs[0].noise_text} | {ch} | " + " | ".join(row) + f" | {fmt(*d, sign=True)} ({other}) |")
    return L + [""]


def maneuver_tables(results, grid, key_cells) -> list[str]:
    L = [f"## {SECTIONS['maneuvers']}", "",
         "RMSE over the maneuver segments (non-zero pitch command, plus 1.5 s settling) and over the level "
         "runs, from the same estimates (the pipeline's scorer with the reference restricted to the "
         "segments). *EKF worst*: GPF − EKF and MMPF − EKF over the maneuvers both below 0; *EKF degrades "
         "most*: its maneuver/level ratio above GPF's and MMPF's (paired per run).", "",
         "| cell | channel | maneuvers GPF / MMPF / EKF | level GPF / MMPF / EKF | ratio GPF / MMPF / EKF | "
         "EKF worst | EKF degrades most |", "|---|---|---|---|---|---|---|"]
    for c in key_cells:
        r = results[c]
        for ch in CH:
            man = " / ".join(_mean(r[lab]["man"][ch]) for lab in ("GPF", "MMPF", "EKF"))
            lev = " / ".join(_mean(r[lab]["level"][ch]) for lab in ("GPF", "MMPF", "EKF"))
            rat = " / ".join(f"{np.nanmean(ratios(r, lab, ch)):.2f}" for lab in ("GPF", "MMPF", "EKF"))
            (w1, w2), ws = ekf_worst(r, ch)
            (g1, g2), gs = ekf_degrades_most(r, ch)
            L.append(f"| {md(c.name)} | {ch} | {man} | {lev} | {rat} | {ws} ({fmt(*w1, sign=True)}; "
                     f"{fmt(*w2, sign=True)}) | {gs} |")
    L += ["", "Over the whole sweep (EKF worst / EKF degrades most, per channel depth, speed, pitch):", "",
          "| sensors | κ | EKF worst | EKF degrades most |", "|---|---|---|---|"]
    for c in grid:
        a = "/".join(ekf_worst(results[c], ch)[1] for ch in CH)
        b = "/".join(ekf_degrades_most(results[c], ch)[1] for ch in CH)
        L.append(f"| {c.noise_text} | {c.kappa:g} | {a} | {b} |")
    return L + [""]


def profile_table(results, cells) -> list[str]:
    L = [f"## {SECTIONS['profiles']}", "",
         "The same question on random maneuvering schedules (`--dataset-param profile_seed=K`, "
         "`replay.sim.lake_depth.random_profile`: dives, climbs and pitch-step trains of random length, "
         "amplitude and speed). Per profile: GPF − MMPF / MMPF − EKF (paired) and the ordering; *over the "
         "profiles*: the mean of the per-profile differences with a 95 % interval over the profiles "
         "(the profiles as the random factor).", "",
         "| κ | profile | depth | speed | pitch |", "|---|---|---|---|---|"]
    for k in dict.fromkeys(c.kappa for c in cells):
        cs = [c for c in cells if c.kappa == k]
        per = {ch: [] for ch in CH}
        for c in cs:
            row = []
            for ch in CH:
                d1, d2, st = ordering(results[c], ch)
                per[ch].append((d1[0], d2[0]))
                row.append(f"{fmt(*d1, sign=True)} / {fmt(*d2, sign=True)} {st}")
            L.append(f"| {k:g} | {c.profile} | " + " | ".join(row) + " |")
        pooled = []
        for ch in CH:
            a, b = np.array(per[ch]).T
            d1, d2 = paired(a, np.zeros_like(a)), paired(b, np.zeros_like(b))
            held = sum(ordering(results[c], ch)[2] == "holds" for c in cs)
            pooled.append(f"{fmt(*d1, sign=True)} / {fmt(*d2, sign=True)} {status([d1, d2])} "
                          f"(holds on {held}/{len(cs)})")
        L.append(f"| {k:g} | over the profiles | " + " | ".join(pooled) + " |")
    return L + [""]


def ablation_table(results, cells) -> list[str]:
    L = [f"## {SECTIONS['ablation']}", "",
         "GPF with one part changed, on the same runs and the same filter random stream (common random "
         "numbers). Per channel: the variant's mean RMSE, and variant − GPF (paired; > 0: the part helps). "
         "*Eq. 12 derived*: the continuous GM(1,1) response z1(n+1) − z1(n) = (1 − eᵃ)(z0(1) − b/a)e^(−an) "
         "instead of the response of the fitted discrete equation (the default); *eq. 12 as printed*: the "
         "printed factor (1 − e^(−a)), about the negated prediction (`filters/p000/grey.py`).", "",
         "| cell | variant | depth | speed | pitch |", "|---|---|---|---|---|"]
    for c in cells:
        r = results[c]
        L.append(f"| {md(c.name)} | GPF | " + " | ".join(_mean(r["GPF"]["rmse"][ch]) for ch in CH) + " |")
        for lab in ABLATIONS:
            if lab not in r:
                continue
            row = [f"{_mean(r[lab]['rmse'][ch])} ({fmt(*paired(r[lab]['rmse'][ch], r['GPF']['rmse'][ch]), sign=True)})"
                   for ch in CH]
            L.append(f"| {md(c.name)} | {lab} | " + " | ".join(row) + " |")
    return L + [""]


def advantage_table(results, grid) -> list[str]:
    L = [f"## {SECTIONS['advantage']}", "",
         "GPF's lead over the best baseline (MMPF, EKF, UKF, PF; mean RMSE): (best − GPF) / best, in %. "
         "Positive: GPF is the most accurate. κ smaller: the motion model knows less of the maneuvers; "
         "sensors further below R: the fixed R knows less of the sensors.", "",
         "| sensors | κ | depth | speed | pitch |", "|---|---|---|---|---|"]
    for c in grid:
        L.append(f"| {c.noise_text} | {c.kappa:g} | "
                 + " | ".join(f"{100 * advantage(results[c], ch):+.0f} %" for ch in CH) + " |")
    return L + [""]


def cost_table(results, grid) -> list[str]:
    L = [f"## {SECTIONS['cost']}", "",
         "Filter time per step (µs; the leaderboards' `us_per_step`: the median over a cell's runs, computed as "
         "one batch) and GPF/MMPF, per sweep cell. Measured on a shared 2-core machine while other work ran: "
         "the ratio of two filters of one cell means more than the values.", "",
         "| sensors | κ | " + " | ".join(MAIN) + " | GPF/MMPF |", "|---|---|" + "---|" * (len(MAIN) + 1)]
    for c in grid:
        us = {lab: results[c][lab]["row"]["us_per_step"] for lab in MAIN}
        L.append(f"| {c.noise_text} | {c.kappa:g} | " + " | ".join(f"{v:.0f}" for v in us.values())
                 + f" | {us['GPF'] / us['MMPF']:.2f} |")
    return L + [""]


def every_cell(results, commands, cells) -> list[str]:
    L = ["## Every cell", "",
         "Each cell's leaderboard rows (mean ± 95 % interval over runs of the per-run RMSE: depth m, speed m/s, "
         "pitch rad; median of the depth RMSE; `lost`: depth error above 1 m for 10 consecutive samples, "
         "the depth task's rule), with the commands that compute it.", ""]
    for c in cells:
        labs = [lab for lab in (*MAIN, *ABLATIONS) if lab in results[c]]
        L += [f"### {c.name}", "", result_rows([results[c][lab]["row"] for lab in labs],
                                                metrics=("depth_rmse", "speed_rmse", "pitch_rmse"), names=labs,
                                                digits=4), ""]
        L += [f"`{cmd}`" + "  " for cmd in commands[c]] + [""]
    return L


def plot(path, cells, results, t, segments) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, len(cells), figsize=(5.5 * len(cells), 8), sharex=True, squeeze=False)
    for col, c in enumerate(cells):
        for j, ch in enumerate(CH):
            ax = axes[j, col]
            for a, b, _ in segments:
                ax.axvspan(a, b, color="0.9")
            for lab in MAIN:
                ax.plot(t, results[c][lab]["curves"][ch], lw=1, label=lab)
            ax.set_yscale("log")
            ax.set_ylabel(f"{ch} RMSE ({dict(CHANNELS)[ch]})")
            if j == 0:
                ax.set_title(c.name, fontsize=9)
    axes[0, 0].legend(fontsize=7, ncol=3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s); grey: maneuver segments")
    fig.suptitle("Paper 000, synthetic lake trial: RMSE across Monte Carlo runs at each step")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _d(r, lab, base="GPF") -> str:
    """variant - base per channel (paired), as 'depth / speed / pitch'."""
    return " / ".join(fmt(*paired(r[lab]["rmse"][ch], r[base]["rmse"][ch]), sign=True) for ch in CH)


def _lost(f) -> str:
    return f"{sum(bool(x) for x in f['lost'])}/{len(f['lost'])}"


def reading(results, printed, ablation) -> list[str]:
    """What drives the verdicts, with the numbers quoted from the results (cells missing in quick mode skipped)."""
    from .p000_cells import Cell

    L = ["## Reading", "", "What drives the verdicts (numbers from the tables above; depth / speed / pitch in m, "
         "m/s, rad; paired differences with 95 % intervals):", ""]
    r = results.get(printed)
    if r:
        fixed = f" GPF with the fixed R instead of its wavelet R: {_d(r, 'GPF with the fixed R')}." if (
            "GPF with the fixed R" in r) else ""
        wins = sum(status([paired(r["EKF"]["rmse"][ch], r["GPF"]["rmse"][ch])]) == "holds" for ch in CH)
        L.append("* **At the paper's Q** (κ = 1) the motion model is a random walk of 1 m/s and 0.5 rad per step: "
                 "it never mismatches a maneuver, so what decides is how much each filter smooths. With the "
                 "sensors as generated, far below the fixed R, the EKF with that R is a heavy smoother of a "
                 f"smooth track: it beats GPF in {wins}/3 channels (EKF − GPF: {_d(r, 'EKF')}), while GPF weighs "
                 f"with the small wavelet R and follows the measurements.{fixed}")
    r = results.get(Cell(None, 1e-4))
    if r:
        text = ("* **With a small Q** (κ = 1e-4, sensors as generated) the model cannot turn with the vehicle. "
                f"The EKF lags through the maneuvers (pitch RMSE {_mean(r['EKF']['man']['pitch'])} there, "
                f"{_mean(r['EKF']['level']['pitch'])} on the level runs); the bootstrap PF, whose fixed R barely "
                f"pulls a cloud that Q keeps narrow, loses the track in {_lost(r['PF'])} runs; MMPF follows with "
                "its pitch-rate modes.")
        if "GPF without grey particles" in r:
            text += (f" GPF without grey particles (the bootstrap PF with the wavelet R) loses "
                     f"{_lost(r['GPF without grey particles'])}; its RMSE minus GPF's: "
                     f"{_d(r, 'GPF without grey particles')} — the grey particles' share; the fixed R instead of "
                     f"the wavelet R: {_d(r, 'GPF with the fixed R')}.")
        base = results.get(printed)
        if base:
            text += (" The EKF's lag outlasts the maneuver segments (its speed RMSE over the level runs: "
                     f"{_mean(r['EKF']['level']['speed'])} here, {_mean(base['EKF']['level']['speed'])} at κ = 1; "
                     "see the figure), which is why its maneuver/level ratio need not be the largest even where it "
                     "is the worst during the maneuvers.")
        held = [ch for ch in CH if ordering(r, ch)[2] == "holds"]
        L.append(text + " This is the case GPF is made for; GPF < MMPF < EKF holds there in "
                 + (", ".join(held) if held else "no channel") + ".")
    r = results.get(Cell(1.0, 1e-4))
    if r and "GPF with the fixed R" in r:
        L.append("* **With the sensors at the fixed R** (ρ = 1, κ = 1e-4) the wavelet R equals the fixed R on "
                 f"average (fixed R − GPF: {_d(r, 'GPF with the fixed R')}), and the grey particles, drawn around "
                 "a GM(1,1) extrapolation of measurements as noisy as R (5 m/s in speed), pull the estimate "
                 f"with them: without them − GPF: {_d(r, 'GPF without grey particles')}.")
    rows = [(c, results[c]) for c in ablation if "GPF, GM(1,1) eq. 12 derived" in results[c]]
    if rows:
        gap = max(abs(paired(r["GPF, GM(1,1) eq. 12 derived"]["rmse"][ch], r["GPF"]["rmse"][ch])[0])
                  for _, r in rows for ch in CH)
        L.append("* **GM(1,1) response**: eq. 12 derived from eq. 11 and the discrete response differ by at most "
                 f"{gap:.2g} in mean RMSE over the ablation cells (the conditioning shift makes |a| tiny, where "
                 "the two agree to first order). Eq. 12 with the printed factor (1 − e^(−a)) predicts about −z: "
                 "its grey particles get no weight, a tenth of the particles is wasted, and the filter is close to "
                 "GPF without grey particles (printed − without grey particles, a different particle draw: "
                 + "; ".join(f"{c.noise_text}, κ = {c.kappa:g}: "
                             + _d(r, "GPF, GM(1,1) eq. 12 as printed", "GPF without grey particles")
                             for c, r in rows if "GPF without grey particles" in r) + ").")
    L += ["* **Fair baselines**: the paper gives EKF and MMPF the same Q as GPF; the table of each filter at "
          "its best κ answers whether GPF wins only because the baselines were mistuned (summary under the "
          "verdict).", "",
          "Checks that the filters are not the cause: on a near-linear depth model with small known Q and R, the "
          "bootstrap PF inside GPF, a one-mode MMPF and GPF with wavelet R agree with the EKF to a fraction of "
          "its error (`tests/test_gpf.py::test_particle_filters_agree_with_ekf_on_a_near_linear_model`). Whether "
          "the paper's ordering appears with its real lake-trial data (and its unstated units) cannot be "
          "checked.", ""]
    return L
