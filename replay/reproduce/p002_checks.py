"""Part ``tables`` of the paper-002 reproduction (2/2): STCKF as printed, the position-error definition,
the IGWO entropy weights, the geometry of the sonar benchmark.

:func:`jobs` lists the evaluations; :func:`render` takes them with the Table 5 / 6
rows of :mod:`.p002_sim` and returns Markdown and claims.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from replay.filters.p002 import compiled_util
from replay.reproduce.verdict import Claim, anchor

from .p002_common import PSO_LB, PSO_UB, SONAR, TABLE5, TABLE6, Job, n100
from .p002_tables import DEFINITIONS, cell, commands, definitions, entries, find, fmt, ok_runs, pm, table

H_STCKF = "STCKF as printed"
H_DEF = "Which position error"
H_ENTROPY = "IGWO entropy weights invert the leader order"
H_GEO = "Geometry sensitivity"
STCKF_VARIANTS = {
    "printed M": {"m_form": "printed"},
    "printed M, unscaled prior (as printed)": {"m_form": "printed", "scale_prior": False},
    "as printed + PSD repair": {"m_form": "printed", "scale_prior": False, "repair": True},
    "unscaled prior + PSD repair": {"scale_prior": False, "repair": True},
}
GEO_FILTERS = ("ckf", "stckf", "pf", "pso-pf", "igwo-stcpf")
GEOMETRY = {
    "noiseless": ("truth without process noise", {"truth_noise": False}),
    "box": ("noiseless, pitch 0.3 rad: |z| ≤ 300 m, range ≤ 300 m",
            {"truth_noise": False, "x0": [0.0, 0.0, 0.0, 10.0, 0.3, float(np.pi / 10)]}),
    "short": ("Table 2 with process noise, horizon 40 s", {"steps": 40}),
}
RANGE_BINS = (0, 100, 200, 300, 500, 700, np.inf)


def jobs(s) -> list[Job]:
    out = [Job(f"stckf:{name}", f"STCKF {name}", *SONAR, ("stckf",), s.mc, {"stckf": p})
           for name, p in STCKF_VARIANTS.items()]
    for key, (label, dp) in GEOMETRY.items():
        out.append(Job(f"geo:{key}", f"geometry: {label}", *SONAR, GEO_FILTERS, s.mc, n100("pf"), dp))
    return out


def lam_stats(e) -> dict:
    lam = [np.asarray(est.info.get("lambda", []), float) for est in e.result.estimates]
    lam = np.concatenate(lam) if lam else np.zeros(0)
    rep = [est.info.get("covariance_repairs", 0) for est in e.result.estimates]
    if not len(lam):
        return {"λ median": "—", "λ > 1": "—", "λ max": "—", "repairs/run": "—"}
    return {"λ median": f"{np.median(lam):.3g}", "λ > 1": f"{100 * np.mean(lam > 1):.0f} %",
            "λ max": f"{lam.max():.3g}", "repairs/run": f"{np.mean(rep):.1f}"}


def box_share(ev) -> tuple[float, float]:
    """(share of steps with |z| > 300, the largest range) of the truths of ``ev`` (positions only)."""
    z = np.concatenate([t[:, 2] for t in ev.truths])
    rng = max(float(np.linalg.norm(t, axis=1).max()) for t in ev.truths)
    return float(np.mean((z < PSO_LB[2]) | (z > PSO_UB[2]))), rng


def range_table(rows, evs_named) -> list[str]:
    """RMSE of the horizontal error per range bin, over runs and steps (pooled), per filter."""
    bins = RANGE_BINS
    head = [f"{bins[i]:g}–{bins[i + 1]:g} m" if np.isfinite(bins[i + 1]) else f"> {bins[i]:g} m"
            for i in range(len(bins) - 1)]
    lines = ["| trajectory | filter | " + " | ".join(head) + " |", "|" + "---|" * (len(head) + 2)]
    for traj, ev_rows in evs_named:
        for e in ev_rows:
            rng, err = [], []
            for i in ok_runs(e.result):
                rng.append(np.linalg.norm(e.ev.truths[i], axis=1))
                err.append(np.sum(e.result.errors[i]["position"][:, :2] ** 2, axis=1))
            r, d = np.concatenate(rng), np.concatenate(err)
            cells = []
            for lo, hi in zip(bins[:-1], bins[1:]):
                sel = (r >= lo) & (r < hi) & np.isfinite(d)
                cells.append(f"{np.sqrt(d[sel].mean()):.2f} ({sel.sum()})" if sel.sum() >= 10 else "—")
            lines.append(f"| {traj} | {e.name} | " + " | ".join(cells) + " |")
    return lines


def render(evs, s, sim) -> tuple[list[str], list[Claim]]:
    out, claims = [], []
    rows5, rows6 = sim["rows5"], sim["rows6"]

    # STCKF as printed
    base = [replace(find(rows5, "stckf"), name="stckf (default: propagated M, scaled prior)", extra={}),
            replace(find(rows5, "ckf (baseline)"), extra={})]
    variants = [entries(evs[f"stckf:{n}"], {"stckf": f"stckf ({n})"})[0] for n in STCKF_VARIANTS]
    rows = [base[0]] + variants + [base[1]]
    for e in rows:
        e.extra.update(lam_stats(e))
    out += [f"## {H_STCKF}", "",
            "With M = H Φ Hᵀ as printed the fading factor λ = max(1, tr(N) / tr(M)) does not scale with the "
            "state's uncertainty (tr(H Φ Hᵀ) is O(1) in the range row, O(1/r²) in the bearing rows); with the "
            "scaled prior it multiplies P by λ every step until P overflows, and the update as printed "
            "(P = P⁻ − K S Kᵀ with only P_zz, P_xz scaled) turns indefinite within a few steps. Our default uses "
            "the propagated M = H Φ P Φᵀ Hᵀ and scales the prior too (`filters/p002/stckf.py`). "
            "Rows: the default, the print "
            "(with and without an eigenvalue-floor repair of the posterior covariance, `-p stckf.repair=true`), "
            "and the CKF (λ ≡ 1) as the baseline. λ statistics over every update of every run (until divergence); "
            "a run whose covariance is not positive definite counts as diverged (left out of the means).", ""]
    out += table(rows, ("pos", "mean3", "median", "lost", "diverged", "λ median", "λ > 1", "λ max",
                        "repairs/run")) + [""] + commands(rows)
    rep = variants[2]
    out += [f"As printed, STCKF diverges in {variants[1].row['diverged']}/{variants[1].row['runs']} runs; with the "
            f"repair it runs ({pm(rep.pair())} m, {rep.extra['repairs/run']} repairs per run) but is not better "
            f"than the default ({pm(base[0].pair())}) nor than the CKF ({pm(base[1].pair())}). The printed M with "
            "the scaled prior multiplies P by λ every step until it overflows: no repair helps "
            f"({variants[0].row['diverged']}/{variants[0].row['runs']} diverged).", ""]

    # which position error
    out += [f"## {H_DEF}", "",
            "The paper's 'position' is smaller than √(X² + Y²) of its own columns (Table 5 STCKF: 1.3373 < "
            "√(0.9998² + 1.0090²) = 1.4205), so it is not a horizontal RMSE. Nor can it be the per-run horizontal "
            "RMSE averaged (`rmse2`): with X_r, Y_r the per-run RMSEs, mean_r √(X_r² + Y_r²) ≥ √(X̄² + Ȳ²) "
            "(the norm is convex), so that ratio is ≥ 1 while the paper's is < 1. Per definition, ours from the "
            "same runs (mean ± 95 %) and the ratio definition ÷ √(X̄² + Ȳ²), beside the paper's ratio:", ""]
    out += [f"* `{k}`: {v}" for k, v in DEFINITIONS.items()] + [""]
    out += ["| table | filter | paper ratio | " + " | ".join(f"{k} (ratio)" for k in DEFINITIONS) + " |",
            "|" + "---|" * (3 + len(DEFINITIONS))]
    fit = {t: {k: [] for k in DEFINITIONS} for t in ("Table 5", "Table 6")}
    for title, rows_t, paper in (("Table 5", rows5, TABLE5), ("Table 6", rows6, TABLE6)):
        for e in rows_t:
            p = paper.get(e.result.name)
            if p is None or e.extra.get("variant"):
                continue
            pr = p[0] / np.hypot(p[1], p[2])
            h = np.hypot(e.value("x_rmse"), e.value("y_rmse"))
            defs = definitions(e.result)
            cells = []
            for k in DEFINITIONS:
                v, ci = cell(defs[k])
                if e.row.get("lost") in (0, "0", 0.0):
                    fit[title][k].append(abs(v / h - pr))
                cells.append(f"{v:.3f} ± {ci:.3f} ({v / h:.3f})")
            out.append(f"| {title} | {e.name} | {pr:.3f} | " + " | ".join(cells) + " |")
    said = []
    for title, f in fit.items():
        score = {k: float(np.mean(v)) if v else np.nan for k, v in f.items()}
        if not any(np.isfinite(v) for v in score.values()):
            continue
        best = min(score, key=lambda k: score[k] if np.isfinite(score[k]) else np.inf)
        said.append(f"{title}: `{best}` (mean absolute difference of ratios: "
                    + ", ".join(f"{k} {fmt(v)}" for k, v in score.items()) + ")")
    out += ["", "The per-run horizontal RMSE gives a ratio of about 1 whatever the filter (1.00–1.03 above), while "
            "the paper's ratios run from 0.84 to 1.65: it fits no table. Over the rows without lost runs, the "
            "definition closest to the paper's ratios is, per table, " + "; ".join(said) + ". The paper's Table 5 "
            "ratios below 1 fit the mean 3-D Euclidean error, its Table 6 ratios above 1 a 3-D error: the two "
            "tables may not use one definition. Every table of this document gives the mean 3-D error beside the "
            "3-D RMSE; the position column is the 3-D RMSE (`pos_rmse`).", ""]

    # entropy weights
    examples = ([1.0, 1.5, 10.0], [1.0, 2.0, 3.0], [1.0, 1.0, 1.0], [0.1, 1.0, 10.0], [1.0, 10.0, 100.0])
    out += [f"## {H_ENTROPY}", "",
            "IGWO weights the three leaders by 1 − E_i, E_i = −p_i log p_i with p_i ∝ 1/f_i (002 §3.2.2; "
            "`compiled_util.entropy_weights`, the kernel's own function). E is largest at p = 1/e, so the weight "
            "is not monotone in the fitness (smaller f is better):", "",
            "| leader fitness f (α, β, δ) | p | weights w̃ (α, β, δ) | order kept |", "|---|---|---|---|"]
    inverted = None
    for f in examples:
        fl, w = np.array(f), np.empty(3)
        compiled_util.entropy_weights(fl, 1e-12, 1e-4, w)
        p = (1 / fl) / np.sum(1 / fl)
        kept = bool(w[0] >= w[1] >= w[2])
        if f == examples[0]:
            inverted = w
        out.append(f"| {', '.join(f'{v:g}' for v in f)} | {', '.join(f'{v:.3f}' for v in p)} | "
                   f"{', '.join(f'{v:.3f}' for v in w)} | {'yes' if kept else '**no**'} |")
    out += ["", "The weights stay within about [0.28, 0.40] (1 − E ∈ [1 − 1/e, 1]), close to GWO's 1/3 each; for "
            f"f = [1, 1.5, 10] the worst leader (δ) weighs most ({inverted[2]:.3f}) and β least ({inverted[1]:.3f}). "
            "Test: `tests/test_paper002.py::test_entropy_weights_invert_the_leader_order`.", ""]
    claims.append(Claim("IGWO entropy weights give the better leaders more weight (§3.2.2)",
                        f"f = [1, 1.5, 10] → w̃ = [{', '.join(f'{v:.3f}' for v in inverted)}]", "stated",
                        "not reproduced", anchor(H_ENTROPY)))

    # geometry
    out += [f"## {H_GEO}", "",
            "Table 2's process noise makes speed, pitch and yaw random walks (pitch s.d. 1 rad after 100 s) and "
            "the AUV dives ~700 m in 100 s, so ranges reach several hundred metres and the 0.01 rad bearing noise "
            "is several metres across. Variants of the simulator (`replay/sim/auv_sonar.py`): the truth without "
            "process noise (the same sonar noise draws; the filters still assume Table 2's Q), the same at pitch "
            "0.3 rad (|z| ≤ 300 m, range ≤ 300 m: inside the paper's PSO box), and the noisy truth over 40 s.", ""]
    geo = {}
    for key, (label, _) in GEOMETRY.items():
        ev = evs[f"geo:{key}"]
        zshare, rmax = box_share(ev)
        rows_g = entries(ev, {"pf": "pf (N = 100)", "pso-pf": "pso-pf (bounded, 002)"})
        geo[key] = rows_g
        out += [f"### {label}", "", f"Steps with z outside [−300, 0]: {100 * zshare:.1f} %; largest range "
                f"{rmax:.0f} m.", ""]
        out += table(rows_g, ("pos", "mean3", "x", "y", "pitch", "yaw", "median", "lost", "diverged")) + [""]
        out += commands(rows_g)
    box_ckf, box_st = find(geo["box"], "ckf"), find(geo["box"], "stckf")
    out += ["Horizontal RMSE (m) against the true range, pooled over runs and steps (number of samples in "
            "brackets): the error grows with range, as bearing noise does.", ""]
    out += range_table(None, [("Table 2", [e for e in rows5 if e.name in ("stckf", "ckf (baseline)", "igwo-stcpf")]),
                              ("noiseless", [e for e in geo["noiseless"] if e.name in ("stckf", "ckf", "igwo-stcpf")])])
    out += ["", f"Inside the paper's box (noiseless, pitch 0.3 rad) the STCKF's X / Y errors are "
            f"{pm(box_st.pair('x_rmse'))} / {pm(box_st.pair('y_rmse'))} m against the paper's 0.9998 / 1.0090 "
            f"(Table 2 geometry: {pm(find(rows5, 'stckf').pair('x_rmse'))} / "
            f"{pm(find(rows5, 'stckf').pair('y_rmse'))}); the ~2× gap of Table 5 in X / Y is geometry. The CKF "
            f"there: {pm(box_ckf.pair('x_rmse'))} / {pm(box_ckf.pair('y_rmse'))}.", ""]
    igwo_box = find(geo["box"], "igwo-stcpf")
    out += [f"IGWO-STCPF inside the box: {pm(igwo_box.pair())} m (paper 1.1579), still above the CKF "
            f"({pm(box_ckf.pair())}) and the STCKF ({pm(box_st.pair())}): its gap to the paper is not geometry "
            "alone.", ""]
    return out, claims
