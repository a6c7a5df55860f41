"""The document of the paper-003 reproduction (:mod:`.p003`): verdicts, tables, plot."""
from __future__ import annotations

import numpy as np

from replay.scoring.metrics import paired

from .common5 import combine, commands, paired_cell, rmse_curve, row, table
from .p003_plan import ACCEL, CONTRAST, MISMATCH, N_BASE, N_PRINTED, N_SWEEP, ROUGHENING, likelihoods
from .p003_plots import FILTERS, plots, run_errors
from .verdict import Claim, anchor, verdict_table

S_PRINTED = "Printed setting"
S_WHY = "Why no effect can show at the printed setting"
S_WHERE = "Where, if anywhere, α < 1 helps"
S_N = "Sweep of the particle count N"
S_Q = "Sweep of the process noise"
S_C = "Sweep of the glint contrast and probability"
S_M = "Mismatched Gaussian likelihood"
EARLY, LATE = slice(20, 40), slice(80, 100)  # steps 21-40 and 81-100 (the prior's transient is over by 20)


def kurtosis(ratio: float, eps: float) -> float:
    """Excess kurtosis of the bearing noise (1 − ε) N(0, σ₁²) + ε N(0, (ratio σ₁)²)."""
    m2 = (1 - eps) + eps * ratio**2
    m4 = 3 * ((1 - eps) + eps * ratio**4)
    return m4 / m2**2 - 3


def errors(ev, i):
    """Per-run position-error norms (runs, n) of filter ``i`` (NaN rows for diverged runs)."""
    out = []
    for rec, err in zip(ev.results[i].runs, ev.results[i].errors):
        e = np.linalg.norm(np.asarray(err["position"], float), axis=-1)
        out.append(np.full_like(e, np.nan) if rec.get("diverged") else e)
    return np.array(out)


def growth(ev, i):
    """Per run: RMS error over steps 81–100 minus RMS error over steps 21–40 (m)."""
    e = errors(ev, i)
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.mean(e[:, LATE] ** 2, axis=1)) - np.sqrt(np.mean(e[:, EARLY] ** 2, axis=1))


def delta(rows, label):
    """(d, h) of the paired pos_rmse column of the row ``label``."""
    return pair(next(r for r in rows if r["label"] == label))


def pair(r):
    """(d, h) of a combined row's paired pos_rmse column (NaN for the baseline)."""
    try:
        return float(r["pos_rmse_vs_base"]), float(r["pos_rmse_vs_base_ci95"])
    except (KeyError, TypeError, ValueError):
        return np.nan, np.nan


def fmt(dh, digits=2):
    x, h = dh
    return "n/a" if not np.isfinite(x) else f"{x:+.{digits}f} ± {h:.{digits}f}"


def block(title, rows, intro, metrics=("pos_rmse",)):
    return [f"## {title}", "", intro, "", table(rows, metrics=metrics, base_name="the setting's PF"), "",
            "Commands (one per row):", "", commands(rows), ""]


A1, BOOT = "PF = WF-PF α = 1 (baseline)", "PF (bootstrap, own particle stream)"


def render(evs, runs, seed, quick, doc) -> str:
    where = []  # (setting, {alpha: Δ vs α = 1, "paper": Δ WF-PF 0.75 − PF, "floor": Δ α = 1 − PF})

    def record(label, rows, prefix=""):
        g = {a: delta(rows, f"{prefix}WF-PF α = {a}") for a in (0.75, 0.5, 0.25)
             if any(r["label"] == f"{prefix}WF-PF α = {a}" for r in rows)}
        where.append((label, g))

    def paper_pair(ev):
        """WF-PF (α = 0.75) − PF in the evaluation that holds both (separate particle streams)."""
        r = ev.rows[1]
        try:
            return float(r["pos_rmse_vs_pf"]), float(r["pos_rmse_vs_pf_ci95"])
        except (KeyError, TypeError, ValueError):
            return np.nan, np.nan

    # ---- printed setting
    p = evs["printed"]
    printed = combine([("PF", row(p, "pf")), ("WF-PF α = 0.75 (the paper)", row(p, "wf-pf")),
                       ("WF-PF α = 0.5", row(evs["printed a=0.5"])), ("WF-PF α = 0.25", row(evs["printed a=0.25"])),
                       ("WF-PF α = 1 (weight floor only)", row(evs["printed a=1"])),
                       (f"PF + roughening K = {ROUGHENING}", row(evs["printed rough"])),
                       ("UKF (R = mixture covariance)", row(p, "ukf")), ("EKF", row(p, "ekf"))],
                      metrics=("pos_rmse", "x_rmse", "y_rmse"))
    pr_alpha = combine([("WF-PF α = 1", row(evs["printed a=1"])), ("WF-PF α = 0.75", row(p, "wf-pf")),
                        ("WF-PF α = 0.5", row(evs["printed a=0.5"])), ("WF-PF α = 0.25", row(evs["printed a=0.25"]))])
    record(f"printed (N = {N_PRINTED}, σ₂/σ₁ = 2, ε = 0.75)", pr_alpha)
    where[-1][1]["paper"] = paper_pair(p)
    g_pf, g_wf = growth(p, 0), growth(p, 1)
    run_errs = {name: run_errors(p, i) for name, i in FILTERS}  # |x|, |y| errors per run: the peaks and plots
    peak = {n: tuple(float(np.nanmax(rmse_curve(e[k]))) for k in ("x", "y")) for n, e in run_errs.items()}

    # ---- sweeps: baseline WF-PF α = 1 (the PF, same particle stream as the α < 1 rows)
    def sweep(key, label, extra=(), key_a1=None, key_half=None, alphas=(0.75, 0.5)):
        ev = evs[key]
        items = [(A1, row(evs[key_a1 or f"{key} a=1"])), (BOOT, row(ev, "pf")), ("WF-PF α = 0.75", row(ev, "wf-pf")),
                 ("WF-PF α = 0.5", row(evs[key_half or f"{key} a=0.5"]))]
        if 0.25 in alphas:
            items.append(("WF-PF α = 0.25", row(evs[f"{key} a=0.25"])))
        rows = combine(items + list(extra))
        record(label, rows)
        where[-1][1]["paper"] = paper_pair(ev)
        for r in rows:
            r["label"] = f"{label}: {r['label']}"
        return rows

    n_rows = []
    for n in N_SWEEP:
        n_rows += sweep(f"N={n}", f"N = {n}")
    q_rows = []
    for s in sorted(ACCEL + (1.0,)):
        rough = "accel=1.0 rough" if s == 1.0 else f"accel={s} rough"
        extra = [(f"PF + roughening K = {ROUGHENING}", row(evs[rough]))]
        if s == 1.0:
            q_rows += sweep(f"N={N_BASE}", f"σ_a = {s}", extra=extra)
        else:
            q_rows += sweep(f"accel={s}", f"σ_a = {s}", extra=extra)
    c_rows = []
    for ratio, eps in CONTRAST:
        k = f"contrast {ratio} eps={eps}"
        c_rows += sweep(k, f"σ₂/σ₁ = {ratio}, ε = {eps}", extra=[("UKF", row(evs[k], "ukf"))])
    m_rows, m_help = [], {}
    for ratio, eps in MISMATCH:
        for lik, task_eps in likelihoods(ratio, eps):
            k = f"mismatch {ratio} eps={eps} {lik}"
            what = "thermal core N(0, σ₁²)" if lik == "core" else "glint component N(0, σ₂²)"
            extra = [("WF-PF α = 0.5, no floor (1e−300)", row(evs[f"{k} a=0.5 nofloor"]))] if lik == "core" else []
            m_rows += sweep(k, f"σ₂/σ₁ = {ratio}, ε = {eps}, filter assumes the {what}", extra=extra,
                            alphas=(0.75, 0.5, 0.25) if lik == "core" else (0.75, 0.5))
            m_help[(ratio, eps, lik)] = where[-1][1]
    # the correctly specified PF on the same glint, for comparison (contrast sweep rows)
    right = {(ratio, eps): next(r for r in c_rows if r["label"] == f"σ₂/σ₁ = {ratio}, ε = {eps}: {A1}")
             for ratio, eps in MISMATCH}

    # ---- verdicts
    ALPHAS = (0.75, 0.5, 0.25)

    def sig(sign):
        return [(s, a, *ds[a]) for s, ds in where for a in ALPHAS
                if a in ds and np.isfinite(ds[a][0]) and sign * (ds[a][0] + sign * ds[a][1]) < 0]

    helps, hurts = sig(1), sig(-1)  # interval below 0 / above 0
    n_cmp = sum(a in ds and np.isfinite(ds[a][0]) for _, ds in where for a in ALPHAS)
    d_pr, h_pr = delta(printed, "WF-PF α = 0.75 (the paper)")
    gp, gw = paired(g_pf, np.zeros_like(g_pf)), paired(g_wf, np.zeros_like(g_wf))
    gd = paired(g_wf, g_pf)
    gu = paired(growth(p, 2), g_pf)
    m_sig = [(s_, a, x, h) for s_, a, x, h in helps if "filter assumes" in s_]
    imp = [w for w in where if w[0] in ("N = 50", "N = 100", "σ_a = 0.03", "σ_a = 0.1")]
    imp_help = [(s, a, *ds[a]) for s, ds in imp for a in ALPHAS if a in ds and ds[a][0] + ds[a][1] < 0]
    rough = {r["label"].split(":")[0]: pair(r) for r in q_rows if "roughening" in r["label"]}
    anc_pr, anc_m, anc_where, anc_q = anchor(S_PRINTED), anchor(S_M), anchor(S_WHERE), anchor(S_Q)
    imp_pf = next(r for r in q_rows if r["label"] == f"σ_a = {ACCEL[0]}: {BOOT}")
    claims = [
        Claim("standard PF: position error up to ~16 m (x) and ~15 m (y) (Fig. 3–4)",
              f"max over t of RMSE(t): x {peak['PF'][0]:.1f} m, y {peak['PF'][1]:.1f} m (printed setting); "
              f"impoverished (σ_a = {ACCEL[0]} m/s², N = {N_BASE}): mean RMSE {imp_pf['pos_rmse']:.1f} m, "
              f"lost {imp_pf['lost']}/{imp_pf['runs']}", "~16 m, ~15 m", "not reproduced", anc_pr),
        Claim("standard PF: the error drifts (grows over the run)",
              f"RMS error steps 81–100 minus 21–40: {fmt((gp['diff'], gp['diff_ci95']))} m; the UKF's "
              f"{fmt(_gr(growth(p, 2)))} m (UKF − PF {paired_cell(growth(p, 2), g_pf, 2)})"
              + (": the same for the UKF" if abs(gu["diff"]) <= gu["diff_ci95"] else ""),
              "grows",
              "reproduced" if gp["diff"] - gp["diff_ci95"] > 0 else "not reproduced", anc_pr),
        Claim("WF-PF (α = 0.75) has clearly smaller position error than the PF",
              f"paired Δ pos_rmse {fmt((d_pr, h_pr), 3)} m (N = {N_PRINTED}, {runs} runs)", "clearly smaller (figures)",
              "reproduced" if d_pr + h_pr < 0 else ("deviation explained" if (imp_help or m_sig) else "not reproduced"),
              anc_where, cause="" if d_pr + h_pr < 0 or not (imp_help or m_sig) else (
                  f"at the printed setting nothing makes α matter (bearing excess kurtosis {kurtosis(2, 0.75):.2f}, "
                  f"the filter knows the glint, N = {N_PRINTED}); α < 1 only flattens the likelihood "
                  "(w ∝ p(z|x)^α) and helps only where the PF impoverishes ("
                  + ("; ".join(f"{s_}, α = {a}: {fmt((x, h))} m" for s_, a, x, h in imp_help) or "nowhere")
                  + ") or its Gaussian likelihood is too sharp ("
                  + ("; ".join(f"α = {a}: {fmt((x, h))} m" for s_, a, x, h in m_sig) or "nowhere")
                  + "), against α = 1 with the same particle noise")),
        Claim("WF-PF: no drift", f"growth {fmt((gw['diff'], gw['diff_ci95']))} m; paired vs PF "
              f"{fmt((gd['diff'], gd['diff_ci95']))} m", "no drift",
              "reproduced" if abs(gw["diff"]) <= gw["diff_ci95"] and gd["diff"] + gd["diff_ci95"] < 0
              else "not reproduced", anc_pr),
        Claim("α < 1 keeps more distinct particles and so improves accuracy where the PF impoverishes "
              "(§3, eq. 28–32)",
              ("; ".join(f"{s}, α = {a}: {fmt((x, h))}" for s, a, x, h in imp_help) if imp_help else
               "no significant gain at N = 50, 100 or σ_a = 0.03, 0.1; α = 0.75 vs α = 1: "
               + ", ".join(f"{s} {fmt(ds[0.75])}" for s, ds in imp))
              + "; roughening vs α = 1: " + ", ".join(f"{k} {fmt(v)}" for k, v in rough.items()
                                                       if k in ("σ_a = 0.03", "σ_a = 0.1")),
              "implied", "reproduced" if imp_help else "not reproduced", anc_q),
    ]

    L = ["# Reproduction of paper 003: weight-factor PF vs PF under glint noise", "",
         f"Generated by `replay reproduce 003 --runs {runs} --seed {seed}{' --quick' if quick else ''}`; "
         "do not edit by hand. Dataset `sim/uav-formation`, task `formation`. Every number comes from "
         "`replay.run.evaluation.evaluate` (the pipeline of `replay eval`): mean over runs ± 95 % Student-t "
         "half-width, median, `lost k/N` (position error above 20 m for the task's `lost_steps`), diverged; "
         "`Δ … (paired)` is this row minus the table's first row, run by run on the same measurements "
         "(common random numbers; the leaderboard's `pos_rmse_vs_<baseline>`), marked *(lower)* / *(higher)* "
         "when the interval excludes 0. A filter's particles are drawn from a stream seeded by its name, so "
         "`pf` and `wf-pf` share the measurements but not the particle noise, while all `wf-pf` rows share "
         "both; the sweeps therefore use WF-PF with α = 1 as the PF (bit for bit the bootstrap PF where the "
         "1e−99 floor does not bind: tests/test_reproduce_003.py) and show the `pf` row beside it — their "
         "difference is particle noise alone.", "",
         "## Verdict", "", verdict_table(claims), "",
         "## Setting", "",
         "* Truth and sensor: replay/sim/uav_formation.py — leader and follower of 003 §4.1 (printed: "
         "x₀, leader start, range σ = 5 m, bearing σ₁ = 0.4°, σ₂ = 0.8°, ε = 0.75); ours (not printed): "
         "T = 1 s, 100 steps in five legs of 20 with turns of 0.05 rad/s, follower acceleration noise "
         "σ_a = 1 m/s² (`accel_sigma`), prior x₀ ~ N(truth, diag(10², 10², 1, 1)) (task `formation`).",
         "* Filters: `pf` (bootstrap, systematic resampling every step), `wf-pf` (eq. 22 floor 1e−99, "
         "eq. 27 exponent α; filters/p003/wfpf.py), `ukf`/`ekf` with R = the mixture's covariance. The "
         "filters use the simulated glint mixture as likelihood unless the task parameter `eps` says "
         "otherwise (section [mismatched Gaussian likelihood](" + anc_m + ")).", ""]

    L += [f"## {S_PRINTED}", "",
          f"N = {N_PRINTED}, σ₂/σ₁ = 2, ε = 0.75, the filter knows the mixture; {runs} runs.", "",
          table(printed, metrics=("pos_rmse", "x_rmse", "y_rmse")), "", "Commands (one per row):", "",
          commands(printed), "",
          "Drift: per run, the RMS position error over steps 81–100 minus that over steps 21–40 (the "
          "prior's transient is over by step 20), from the per-run errors of the same evaluations.", "",
          "| filter | peak of RMSE(t) x / y (m) | growth (m) | growth, paired vs PF (m) |", "|---|---|---|---|",
          f"| PF | {peak['PF'][0]:.2f} / {peak['PF'][1]:.2f} | {fmt((gp['diff'], gp['diff_ci95']))} | – |",
          f"| WF-PF α = 0.75 | {peak['WF-PF'][0]:.2f} / {peak['WF-PF'][1]:.2f} | "
          f"{fmt((gw['diff'], gw['diff_ci95']))} | {fmt((gd['diff'], gd['diff_ci95']))} |",
          f"| UKF | {peak['UKF'][0]:.2f} / {peak['UKF'][1]:.2f} | "
          f"{fmt(_gr(growth(p, 2)))} | {paired_cell(growth(p, 2), g_pf, 2)} |", ""]
    L += plots(p.t, run_errs, doc, "printed setting")

    L += [f"## {S_WHY}", "",
          f"* The glint is nearly Gaussian: the bearing mixture's excess kurtosis is {kurtosis(2, 0.75):.2f} at "
          f"the printed σ₂/σ₁ = 2, ε = 0.75 (0 for a Gaussian; {kurtosis(10, 0.1):.1f} at σ₂/σ₁ = 10, ε = 0.1). "
          "Excess kurtosis of (1 − ε) N(0, σ₁²) + ε N(0, σ₂²): 3[(1 − ε) + ε r⁴]/[(1 − ε) + ε r²]² − 3, "
          "r = σ₂/σ₁ (checked against samples in tests/test_wfpf.py).",
          "* The bearing is not the dominant error: at the ≈ 200 m leader–follower distance (the printed "
          "start; both fly the same turns) 0.8° is ≈ 2.8 m across the line of sight, against 5 m along it "
          "(range σ).",
          "* The filter knows the likelihood, and with resampling at every step (the paper's and ours) the "
          "prior weights are uniform, so eq. 27 gives w ∝ p(z | x)^α: the WF-PF is a PF whose likelihood is "
          "flattened (for a Gaussian N(h(x), R), exactly N(h(x), R/α); tested in tests/test_wfpf.py). With "
          "the exact likelihood this is a mis-specification; it can help only where the likelihood the filter "
          "uses is too sharp (a mismatched model) or where N is so small that flatter weights keep the cloud "
          "alive — the sweeps below look for both.",
          f"* With N = {N_PRINTED} the cloud is rich: UKF − PF = "
          f"{fmt(delta(printed, 'UKF (R = mixture covariance)'), 3)} m (paired).", ""]

    L += [f"## {S_WHERE}", "",
          "Paired Δ pos_rmse (m) of WF-PF with α < 1 against WF-PF with α = 1 (the PF with the same particle "
          "noise) for every setting of the sections below; **bold** where the interval lies below 0 (α < 1 "
          "helps), *italic* where above (it hurts). Last column: the paper's comparison, WF-PF (α = 0.75) − "
          "the `pf` filter (own particle stream).", "",
          "| setting | α = 0.75 | α = 0.5 | α = 0.25 | WF-PF 0.75 − PF |", "|---|---|---|---|---|"]
    for s_, ds in where:
        cells = []
        for a in ALPHAS + ("paper",):
            x, h = ds.get(a, (np.nan, np.nan))
            c = fmt((x, h), 2)
            cells.append(f"**{c}**" if np.isfinite(x) and x + h < 0 else (f"*{c}*" if np.isfinite(x) and x - h > 0
                                                                           else c))
        L.append(f"| {s_} | " + " | ".join(cells) + " |")
    L += ["", f"α < 1 helps (interval below 0) in {len(helps)} of {n_cmp} comparisons against α = 1"
          + (": " + "; ".join(f"{s_} (α = {a}: {fmt((x, h), 2)})" for s_, a, x, h in helps) if helps else "")
          + f"; it hurts in {len(hurts)}"
          + (": " + "; ".join(f"{s_} (α = {a}: {fmt((x, h), 2)})" for s_, a, x, h in hurts) if hurts else "")
          + f". With {n_cmp} comparisons at 95 %, about {0.025 * n_cmp:.1f} would fall below 0 and as many above "
          "by chance alone: a single marginal interval is no finding.", ""]
    best_mis = {}
    for (ratio, eps), r in right.items():
        worst_best = min((float(x["pos_rmse"]), x["label"].split(": ")[-1].replace(" (baseline)", ""),
                          x["label"].split(": ")[0]) for x in m_rows
                         if x["label"].startswith(f"σ₂/σ₁ = {ratio}, ε = {eps},"))
        best_mis[(ratio, eps)] = worst_best
        L.append(f"For reference, at σ₂/σ₁ = {ratio}, ε = {eps} the PF with the correct glint likelihood "
                 f"(section [{S_C.lower()}]({anchor(S_C)})) gets {r['pos_rmse']:.2f} ± {r['pos_rmse_ci95']:.2f} m "
                 f"(lost {r['lost']}/{r['runs']}); the best row with a mismatched Gaussian "
                 f"({worst_best[2].split(', filter ')[-1]}), "
                 f"{worst_best[1]}, gets {worst_best[0]:.2f} m.")
    L.append("")

    L += block(S_N, n_rows, f"Printed glint (σ₂/σ₁ = 2, ε = 0.75), filter knows it; {runs} runs per row. "
               f"N = {N_PRINTED} is the [printed setting]({anc_pr}).")
    L += block(S_Q, q_rows, f"Follower acceleration noise σ_a (truth and filter; ours 1 m/s²), N = {N_BASE}, "
               f"printed glint. Small σ_a leaves the resampled copies almost undiversified (impoverishment); "
               f"roughening (K = {ROUGHENING}, Gordon et al. 1993) is the textbook remedy and the baseline "
               "α < 1 has to beat.")
    L += block(S_C, c_rows, f"Glint contrast σ₂/σ₁ (σ₁ = 0.4°) and probability ε, N = {N_BASE}, the filter "
               "knows the mixture; UKF with R = the mixture covariance as a Gaussian baseline.")
    L += block(S_M, m_rows, f"The filter's likelihood is a Gaussian mismatched to the simulated glint (task "
               "parameter `eps`: 0 = the thermal core N(0, σ₁²) only, too sharp for the glint samples; 1 = the "
               f"glint component N(0, σ₂²) only, too wide for the core), N = {N_BASE}. With the core "
               "Gaussian, α < 1 widens the likelihood towards the glint (R/α); the no-floor row separates "
               "the exponent from the 1e−99 floor, and the `pf` row (no floor) the floor from α = 1.")
    r03 = rough.get("σ_a = 0.03", (np.nan, np.nan))
    L += ["## Conclusions", "",
          f"At the printed setting WF-PF − PF = {fmt((d_pr, h_pr), 3)} m ({runs} paired runs) and UKF − PF = "
          f"{fmt(delta(printed, 'UKF (R = mixture covariance)'), 3)} m; our PF peaks at "
          f"{peak['PF'][0]:.1f} m (x), not the paper's ~16 m — the paper prints neither T nor Q, and with "
          f"σ_a = {ACCEL[0]} m/s² (N = {N_BASE}) the PF's mean RMSE is {imp_pf['pos_rmse']:.1f} m with "
          f"{imp_pf['lost']}/{imp_pf['runs']} runs lost (section [sweep of the process noise]({anc_q})). Against α = 1 "
          f"with the same particle noise, α < 1 significantly helps in {len(helps)} of {n_cmp} comparisons "
          f"and hurts in {len(hurts)} (section [{S_WHERE.lower()}]({anc_where})). Roughening at σ_a = 0.03: "
          f"Δ {fmt(r03)} m against α = 1. "
          + " ".join(f"At σ₂/σ₁ = {ratio}, ε = {eps} the PF that knows the glint ({r['pos_rmse']:.2f} m) "
                     + ("beats" if r["pos_rmse"] < best_mis[(ratio, eps)][0] else "does not beat")
                     + f" the best filter with a mismatched Gaussian ({best_mis[(ratio, eps)][0]:.2f} m)."
                     for (ratio, eps), r in right.items()), ""]
    return "\n".join(L)


def _gr(g):
    p = paired(g, np.zeros_like(g))
    return p["diff"], p["diff_ci95"]
