"""The document of the paper-001 reproduction (:mod:`.p001`): verdicts, tables, plots."""
from __future__ import annotations

import numpy as np

from .common5 import combine, command, commands, row, table
from .p001_plan import ABLATION, B_SWEEP, STRENGTHS, TRACK, TRACKS
from .p001_plots import plots
from .verdict import Claim, anchor, result_rows, verdict_table

METRICS = ("north", "east", "depth", "vx", "vy", "vz", "ax", "ay", "az")
ALL = ("pos_rmse",) + tuple(f"{m}_rmse" for m in METRICS)
CLAIMS = {"depth": "about equal", "north": "lower with AUKF", "east": "lower with AUKF",
          "vx": "lower with AUKF", "vy": "lower with AUKF", "vz": "lower with AUKF",
          "ax": "lower with AUKF", "ay": "lower with AUKF", "az": "lower with AUKF"}
PAPER, QRL, UKF = "AUKF (paper: q̂, p̂, Q̂, R̂)", "AUKF (Q̂, R̂ only)", "UKF"
S_OBS = "North and east are unobservable"
S_B = "Forgetting factor b"
S_ABL = "Ablation: which estimator, which guard"
S_NONE = "No current"
S_Q = "Direction of the process-noise mean estimate"


def s_main(track):
    return {"bottom": "Bottom-lock DVL", "water": "Water-track DVL"}[track]


def d(r, m="pos_rmse"):
    """(Δ, half-width) of a combined row's paired column for metric ``m``."""
    try:
        return float(r[f"{m}_vs_base"]), float(r[f"{m}_vs_base_ci95"])
    except (KeyError, TypeError, ValueError):
        return np.nan, np.nan


def fmt(dh, digits=3):
    x, h = dh
    return "n/a" if not np.isfinite(x) else f"{x:+.{digits}f} ± {h:.{digits}f}"


def by(rows, label):
    return next(r for r in rows if r["label"] == label)


def holds(metric, dh, base):
    """The paper's claim on ``metric`` for a paired Δ = AUKF − UKF; ``base`` is UKF's mean.
    "About equal" needs an interval holding 0 and |Δ| < 20 % of the UKF's mean."""
    x, h = dh
    if not np.isfinite(x):
        return "n/a"
    if CLAIMS[metric] == "about equal":
        return "holds" if x - h <= 0 <= x + h and abs(x) < 0.2 * base else "does not hold"
    return "holds" if x + h < 0 else ("not shown (interval includes 0)" if x - h <= 0 else "does not hold (worse)")


def main_rows(evs, track, s):
    ev = evs[f"{track} {s}"] if s else evs["no current"]
    qr = evs[f"{track} {s} QR"] if s else evs["no current QR"]
    return combine([(UKF, row(ev, "ukf")), (PAPER, row(ev, "aukf")), (QRL, row(qr))], metrics=ALL)


def guards(ev, i=0):
    info = [e.info for e in ev.results[i].estimates]
    return (np.mean([x.get("guard_q", 0) for x in info]), np.mean([x.get("guard_r", 0) for x in info]),
            len(ev.t))


def metric_table(rows):
    u, a, q = by(rows, UKF), by(rows, PAPER), by(rows, QRL)
    L = ["| metric | UKF | AUKF (paper) | AUKF (Q̂, R̂) | Δ paper − UKF | Δ Q̂R̂ − UKF | paper's claim | "
         "paper's AUKF | Q̂R̂ AUKF |", "|---|---|---|---|---|---|---|---|---|"]
    for m in METRICS:
        k = f"{m}_rmse"
        mc = [f"{r[k]:.3f} ± {r[k + '_ci95']:.3f}" for r in (u, a, q)]
        L.append(f"| {m} | " + " | ".join(mc) + f" | {fmt(d(a, k))} | {fmt(d(q, k))} | {CLAIMS[m]} | "
                 f"{holds(m, d(a, k), u[k])} | {holds(m, d(q, k), u[k])} |")
    return "\n".join(L)


def ablation_rows(evs, track, n):
    ev, qr = evs[f"{track} 0.5"].first(n), evs[f"{track} 0.5 QR"].first(n)
    items = [(UKF, row(ev, "ukf")), (PAPER, row(ev, "aukf")), (QRL, row(qr))]
    items += [(f"AUKF {name}", row(evs[f"{track} ablation {name}"])) for name, _ in ABLATION
              if f"{track} ablation {name}" in evs]
    return combine(items, metrics=ALL), items


SINGLE = ("AUKF R̂ only", "AUKF Q̂ only", "AUKF p̂ only", "AUKF q̂ only")


def group_cause(rows, metrics, what):
    """The 'deviation explained' cause of a claim on ``metrics`` from the ablation rows, or '' when
    they do not single out the estimators: some estimator alone must be significantly worse than
    the UKF (paired) on one of ``metrics``. Variants level with the UKF on all of them (interval
    below +20 % of the UKF's mean) are named beside."""
    u = by(rows, UKF) if rows else {}

    def worst(r):
        return max((d(r, f"{m}_rmse") for m in metrics), key=lambda t: t[0] if np.isfinite(t[0]) else -np.inf)

    def is_level(r):
        return all(np.isfinite(d(r, f"{m}_rmse")[0]) and sum(d(r, f"{m}_rmse")) <= 0.2 * u[f"{m}_rmse"]
                   for m in metrics)

    bad = [r for r in rows if r["label"] in SINGLE and worst(r)[0] - worst(r)[1] > 0]
    level = [r for r in rows if r["label"] != UKF and is_level(r)]
    if not bad:
        return ""
    name = lambda r: r["label"].replace("AUKF ", "")  # noqa: E731
    return (f"{what}. Ablation (largest Δ {'/'.join(metrics)} vs UKF, paired): worse with one estimator "
            "alone: " + ", ".join(f"{name(r)} {fmt(worst(r), 2)}" for r in bad)
            + ("; level with the UKF: " + ", ".join(f"{name(r)} {fmt(worst(r), 2)}" for r in level[:3])
               if level else "; no variant is level with the UKF"))


def signed_final(ev, i=0):
    """Per-run signed final error (estimate − truth) north and east (runs, 2), from the run's errors."""
    return np.array([np.nan * np.ones(2) if rec.get("diverged") else np.asarray(e["position"], float)[-1, :2]
                     for rec, e in zip(ev.results[i].runs, ev.results[i].errors)])


def q_direction(evs, n):
    """Rows of the table 'where q̂ points': signed final errors of the UKF and the q̂-only AUKF, and q̂."""
    from replay.scoring.scorer import ci95

    def mc(v, digits=1):
        v = np.asarray(v, float)
        v = v[np.isfinite(v)]
        return f"{v.mean():+.{digits}f} ± {ci95(v):.{digits}f}" if len(v) else "n/a"

    means = {}
    out = ["| setting | UKF final error north / east (m) | q̂-only final error north / east (m) | "
           "q̂-only final q̂ north / east (m/step) |", "|---|---|---|---|"]
    for label, ukf_key, q_key in (("no current", "no current", "no current ablation q̂ only"),
                                  ("bottom lock, 0.5 m/s", "bottom 0.5", "bottom ablation q̂ only"),
                                  ("water track, 0.5 m/s", "water 0.5", "water ablation q̂ only")):
        if q_key not in evs:
            continue
        u, q = signed_final(evs[ukf_key].first(n)), signed_final(evs[q_key])
        qh = np.array([e.info["q_hat"][:2] for e in evs[q_key].results[0].estimates])
        means[label] = qh.mean(axis=0)
        out.append(f"| {label} | {mc(u[:, 0])} / {mc(u[:, 1])} | {mc(q[:, 0])} / {mc(q[:, 1])} | "
                   f"{mc(qh[:, 0], 3)} / {mc(qh[:, 1], 3)} |")
    return out, means


def qtext(means, water_lower: bool):
    """What the q̂ table shows: whether q̂ is the same with and without current (computed)."""
    e = np.array([m[1] for m in means.values()])
    if len(e) < 2:
        return ""
    same = (np.all(e > 0) or np.all(e < 0)) and (e.max() - e.min()) <= 0.25 * np.abs(e).max()
    vals = ", ".join(f"{k}: {m[1]:+.3f}" for k, m in means.items())
    if same:
        return (f"The final q̂ east is about the same in every row ({vals} m/step), with or without a current: "
                "it is a drift of the estimator, not an estimate of the current."
                + (" In water track it points the way the jet flows (east), so it cancels part of the current's "
                   "drift — a coincidence of this mission and this jet, not compensation." if water_lower else ""))
    return (f"The final q̂ east differs between the rows ({vals} m/step): part of it responds to the current; "
            "compare with the no-current row before reading it as compensation.")


def render(evs, runs, sweep_runs, seed, quick, doc) -> str:
    strengths = [s for s in STRENGTHS if f"bottom {s}" in evs]
    main = {(t, s): main_rows(evs, t, s) for t in TRACKS for s in strengths}
    none = main_rows(evs, "bottom", 0)
    abl = {t: ablation_rows(evs, t, sweep_runs)[0] for t in TRACKS if f"{t} ablation q̂ only" in evs}
    floor = {t: combine([("UKF", row(evs[f"{t} noise-free"]))])[0] for t in TRACKS}
    prim, wat = main[("bottom", 0.5)], main[("water", 0.5)]
    a_abl = anchor(S_ABL)

    # ---- verdicts (primary: bottom lock, 0.5 m/s; water track beside it)
    def ours(metrics):
        out = []
        for track, rows in (("bottom", prim), ("water", wat)):
            out.append(f"{TRACK[track]}: " + "; ".join(
                f"{m} Δ {fmt(d(by(rows, PAPER), f'{m}_rmse'))} (Q̂R̂ {fmt(d(by(rows, QRL), f'{m}_rmse'))})"
                for m in metrics))
        return " — ".join(out)

    def verdict(metrics, what, paper="AUKF lower (Fig. 3–5, figures only)"):
        u = by(prim, UKF)
        ok = all(holds(m, d(by(prim, PAPER), f"{m}_rmse"), u[f"{m}_rmse"]) == "holds" for m in metrics)
        title = ("depth RMSE about equal for AUKF and UKF" if metrics == ("depth",)
                 else f"{', '.join(metrics)} RMSE lower with AUKF than with UKF")
        if ok:
            return Claim(title, ours(metrics), paper, "reproduced", anchor(s_main("bottom")))
        cause = group_cause(abl.get("bottom", []), metrics, what)
        return Claim(title, ours(metrics), paper, "deviation explained" if cause else "not reproduced",
                     a_abl if cause else anchor(s_main("bottom")), cause=cause)

    ne_what = ("north/east are unobservable (no measurement depends on them), so what the estimators add there "
               "is never corrected; q̂'s drift is there without any current (["
               + S_Q.lower() + "](" + anchor(S_Q) + "))")
    measured = ("the state is measured; the estimators that make it worse take the model's disagreement with "
                "the sensors for noise or bias")
    claims = [verdict(("depth",), measured, paper="about equal (Fig. 3)"),
              verdict(("north",), ne_what), verdict(("east",), ne_what),
              verdict(("vx", "vy", "vz"), measured), verdict(("ax", "ay", "az"), measured)]
    wp = [d(by(main[("water", s)], lab)) for s in strengths for lab in (PAPER, QRL)]
    comp = any(np.isfinite(x) and x + h < 0 for x, h in wp)
    fl = {t: f"{floor[t]['pos_rmse']:.1f} ± {floor[t]['pos_rmse_ci95']:.1f} m" for t in TRACKS}
    wq = by(abl["water"], "AUKF q̂ only") if "water" in abl and any(
        r["label"] == "AUKF q̂ only" for r in abl["water"]) else None
    q_note = (f"; q̂ only {fmt(d(wq), 1)} ({sweep_runs} runs)" if wq is not None else "")
    q_cause = (f"; the q̂-only variant's lower error in water track is its estimator drift, the same without "
               f"any current ([{S_Q.lower()}]({anchor(S_Q)}))" if wq is not None and sum(d(wq)) < 0 else "")
    claims.append(Claim(
        "the AUKF's virtual noise compensates the model error caused by the current (§3–5)",
        "water track, Δ pos_rmse vs UKF: " + "; ".join(
            f"{s} m/s paper {fmt(d(by(main[('water', s)], PAPER)), 1)}, Q̂R̂ {fmt(d(by(main[('water', s)], QRL)), 1)}"
            for s in strengths) + q_note, "compensated (Fig. 3–4)", "reproduced" if comp else "deviation explained",
        anchor(S_OBS),
        cause="" if comp else (f"with water track the current is an unobservable drift: the UKF with noise-free "
                               f"sensors has {fl['water']} position RMSE against {fl['bottom']} in bottom lock, "
                               f"and no measurement carries the current{q_cause}")))

    L = ["# Reproduction of paper 001: AUKF vs UKF for small-AUV dead reckoning in currents", "",
         f"Generated by `replay reproduce 001 --runs {runs} --seed {seed}{' --quick' if quick else ''}`; do not "
         f"edit by hand. {runs} Monte Carlo runs per configuration in the main tables, {sweep_runs} in the "
         "forgetting-factor sweep and the ablation (their first runs: the same measurements). Dataset "
         "`sim/sauv-current`, task `dead-reckoning`. Every number comes from `replay.run.evaluation.evaluate` (the "
         "pipeline of `replay eval`): per-run RMSE (m, m/s, m/s²), mean over runs ± 95 % Student-t half-width, "
         "median, `lost k/N` (the task's 1000 m rule), diverged; `Δ … (paired)` is this row minus the UKF, run "
         "by run on the same measurements (common random numbers; as the leaderboard's `pos_rmse_vs_<baseline>`), "
         "marked *(lower)* / *(higher)* when the interval excludes 0.", "",
         "## Verdict", "",
         "Primary setting: bottom-lock DVL, current strength 0.5 m/s; the water-track numbers beside them. "
         "Δ = AUKF − UKF, paired.", "", verdict_table(claims), "",
         "## Setting", "",
         "* Truth and sensors: replay/sim/sauv_current.py — the A→G mission of 001 §4 in the meandering jet of "
         "eq. 111–115 (8 m grid), depth gauge 3 % of 50 m, DVL 1 % of speed, accelerometers 0.02 m/s² bias + "
         "0.02 m/(s²√Hz), AHRS 2° (Gauss–Markov, 30 s: ours). `dvl_track` (ours; the paper is silent): "
         "`bottom` measures the velocity over ground, `water` the velocity through the water.",
         "* Model and task: replay/models/sauv.py (eq. 1–13, T = 0.5 s, nominal Q and R ours), "
         "replay/tasks/dead_reckoning.py: z = [depth, v_b, a_b, heading] (eq. 3), no position fix.",
         "* Filters: `ukf`; `aukf` (filters/p001/aukf.py, eq. 92–110, b = 0.98, guard `biased`); `aukf` with "
         "`adapt_means=none` estimates Q̂ and R̂ only: the Sage–Husa adaptive UKF, the fair adaptive baseline "
         "(the paper's algorithm without its mean estimators).", ""]

    # ---- observability
    L += [f"## {S_OBS}", "",
          "No measurement of eq. 3 depends on north or east (H = [0₈ₓ₂ I₈]) and no other state depends on "
          "them (position is only integrated), so the observability matrix has two zero columns: north/east "
          "are unobservable for every filter here. Their estimate is the prior plus the integral of the "
          "estimated over-ground velocity rotated by the estimated heading; its error is the prior's error "
          "plus the integrated velocity and heading errors, plus — with water track — the integral of the "
          "current, which no sensor sees. A filter can improve north/east only through the observable "
          "velocity, acceleration and heading, and a noise estimator cannot learn the current from "
          "innovations that do not contain it. The rows: the UKF with noise-free DVL, accelerometers and AHRS "
          "(the error left is the prior's 1 m per axis, the discretisation and, in water track, the current) "
          "beside the UKF with the simulated sensors, current 0.5 m/s.", ""]
    frows = []
    for t in TRACKS:
        fr = dict(floor[t], label=f"UKF, noise-free sensors, {TRACK[t]}")
        ur = dict(by(main[(t, 0.5)], UKF), label=f"UKF, simulated sensors, {TRACK[t]}")
        frows += [fr, ur]
    L += [result_rows(frows, metrics=("pos_rmse", "north_rmse", "east_rmse")), "",
          "Commands:", "", commands(frows), ""]

    # ---- main tables
    for track in TRACKS:
        L += [f"## {s_main(track)}", "",
              ("Bottom lock: the DVL measures the velocity over ground, so the current's effect on position "
               "is measured and is no model error for the position; what remains of it is the current's "
               "acceleration in the accelerometers." if track == "bottom" else
               "Water track: the DVL measures the velocity through the water; the current is a true "
               "unmodelled drift of the position (section [north and east are unobservable]"
               f"({anchor(S_OBS)}))."), ""]
        for s in strengths:
            rows = main[(track, s)]
            gq, gr, n = guards(evs[f"{track} {s}"], 1)
            L += [f"### {TRACK[track]}, current strength {s} m/s", "",
                  table(rows, metrics=("pos_rmse", "north_rmse", "east_rmse", "depth_rmse")), "",
                  metric_table(rows), "",
                  f"Guard of the paper's AUKF, mean firings per run (of {n} updates): Q̂ {gq:.0f}, R̂ {gr:.0f}.",
                  "", "Commands:", "", commands(rows), ""]
    rows = none
    L += [f"## {S_NONE}", "", "Current strength 0 (bottom lock and water track coincide): no model error from "
          "the current at all.", "", table(rows, metrics=("pos_rmse", "north_rmse", "east_rmse", "depth_rmse")),
          "", metric_table(rows), "", "Commands:", "", commands(rows), ""]

    # ---- forgetting factor
    L += [f"## {S_B}", "", f"b ∈ {{{', '.join(str(b) for b in sorted(set(B_SWEEP) | {0.98}))}}} (001: 0.95–0.99 "
          f"typical), strength 0.5 m/s, {sweep_runs} runs; the UKF row is the baseline of every Δ.", ""]
    best, best_paper = {}, {}
    for track in TRACKS:
        base = evs[f"{track} 0.5"].first(sweep_runs)
        items = [(UKF, row(base, "ukf"))]
        for b in sorted(set(B_SWEEP) | {0.98}):
            if b == 0.98:
                items += [("paper b = 0.98", row(base, "aukf")),
                          ("Q̂R̂ b = 0.98", row(evs[f"{track} 0.5 QR"].first(sweep_runs)))]
            elif f"{track} b={b}" in evs:
                items += [(f"paper b = {b}", row(evs[f"{track} b={b}"])),
                          (f"Q̂R̂ b = {b}", row(evs[f"{track} b={b} QR"]))]
        rows = combine(items, metrics=ALL)
        best[track] = min(rows[1:], key=lambda r: r["pos_rmse"])
        best_paper[track] = min((r for r in rows if r["label"].startswith("paper")), key=lambda r: r["pos_rmse"])
        L += [f"### {TRACK[track]}", "",
              table(rows, metrics=("pos_rmse", "north_rmse", "east_rmse", "depth_rmse", "vx_rmse")), "",
              f"Lowest mean position RMSE: {best[track]['label']}, Δ vs UKF {fmt(d(best[track]))} m.", "",
              "Commands:", "", commands(rows), ""]

    # ---- ablation
    L += [f"## {S_ABL}", "", f"Strength 0.5 m/s, {sweep_runs} runs (the first runs of the main table: the same "
          "measurements). Variants of the one implementation (filters/p001/aukf.py): which estimators run "
          "(`adapt_means`, `adapt_q`, `adapt_r`) and what replaces an indefinite Q̂ or R̂ (`guard`).", ""]
    for track, rows in abl.items():
        _, items = ablation_rows(evs, track, sweep_runs)
        L += [f"### {TRACK[track]}", "",
              *(["Only the variants that could absorb a drift (q̂) and the best variant of bottom lock.", ""]
                if track == "water" else []),
              table(rows, metrics=("pos_rmse", "north_rmse", "east_rmse", "depth_rmse", "vx_rmse"),
                    paired_metrics=("pos_rmse", "depth_rmse")), "",
              "| variant | guard Q̂ | guard R̂ | abs p̂ depth (m) | abs p̂ vx (m/s) | abs q̂ north (m/step) |",
              "|---|---|---|---|---|---|"]
        for label, (ev, i) in items[1:]:
            info = [e.info for e in ev.results[i].estimates]
            g = [(x.get("guard_q", 0), x.get("guard_r", 0)) for x in info]
            p = np.array([x["p_hat"][:2] for x in info]) if "p_hat" in info[0] else np.zeros((1, 2))
            q = np.array([x["q_hat"][0] for x in info]) if "q_hat" in info[0] else np.zeros(1)
            L.append(f"| {label} | {np.mean([a for a, _ in g]):.0f} | {np.mean([b for _, b in g]):.0f} | "
                     f"{np.mean(np.abs(p[:, 0])):.3g} | {np.mean(np.abs(p[:, 1])):.3g} | {np.mean(np.abs(q)):.3g} |")
        L += ["", "Guard: mean firings per run; p̂, q̂: mean over runs of the final estimate's magnitude.", "",
              "Commands:", "", commands(rows), ""]
    if "no current ablation q̂ only" in evs:
        qtab, qmeans = q_direction(evs, sweep_runs)
        L += [f"### {S_Q}", "",
              "The q̂-only variant is the one estimator that could absorb a drift of the position"
              + (f", and in water track it is lower than the UKF (Δ {fmt(d(wq), 1)} m)." if wq is not None
                 and sum(d(wq)) < 0 else "."),
              f"Is its q̂ an estimate of the current? Signed final errors (estimate − truth) and final q̂, "
              f"mean ± 95 % over the {sweep_runs} runs, from the same evaluations (the UKF's first "
              f"{sweep_runs} runs; the q̂-only AUKF without current: "
              f"`{command(evs['no current ablation q̂ only'])}`):", "",
              *qtab, "", qtext(qmeans, wq is not None and sum(d(wq)) < 0), ""]
    L += plots(evs, doc, strengths)

    # ---- implications
    u, a, q = by(prim, UKF), by(prim, PAPER), by(prim, QRL)
    L += ["## What this implies for the paper's claim", "",
          f"North and east cannot be observed with depth gauge, DVL and AHRS alone. In bottom lock the UKF's "
          f"horizontal error ({u['north_rmse']:.1f} m north, {u['east_rmse']:.1f} m east at 0.5 m/s) is close to "
          f"the noise-free floor ({floor['bottom']['pos_rmse']:.1f} m, 3-D): there is little for any filter to "
          f"gain, and the paper's AUKF loses (Δ north {fmt(d(a, 'north_rmse'), 1)} m, east "
          f"{fmt(d(a, 'east_rmse'), 1)} m), as does the Q̂R̂ AUKF (Δ north {fmt(d(q, 'north_rmse'), 1)}, east "
          f"{fmt(d(q, 'east_rmse'), 1)}). In water track the current's integral dominates "
          f"(noise-free floor {floor['water']['pos_rmse']:.1f} m) and it is invisible to the innovations, so "
          "an adaptive estimator cannot remove it; the paired differences of the water-track tables are what "
          "the adaptive filters do to it. A claim that the AUKF lowers the north/east RMSE through the current's "
          "model error therefore needs a sensor that sees position or the current (GPS at the surface, USBL, "
          "a water-track and a bottom-track DVL together); with the sensors of 001 §5 an improvement can only "
          "come from better velocity or heading, and those are the rows of the velocity claims above. The "
          "mechanisms behind our AUKF's losses are in the ablation: q̂ in the unobserved components is a "
          "velocity that nothing corrects; p̂ takes slow model disagreement for a sensor bias; R̂ takes it for "
          "sensor noise and the filter follows the sensors less; Q̂'s update is indefinite at most steps and the "
          "guard decides its value. "
          + f"Over the [forgetting factor]({anchor(S_B)}) b ∈ 0.95–0.99, the paper's AUKF at its best has "
          f"{best_paper['bottom']['label'].replace('paper ', '')} in bottom lock (Δ "
          f"{fmt(d(best_paper['bottom']), 1)} m) and {best_paper['water']['label'].replace('paper ', '')} in "
          f"water track (Δ {fmt(d(best_paper['water']), 1)} m). On linear-Gaussian models with a known-structure "
          "error the same code recovers the truth and beats the UKF (tests/test_aukf.py).", ""]
    return "\n".join(L)
