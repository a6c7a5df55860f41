"""Evidence and tables of the paper-003 reproduction (:mod:`.p003`): per-run values from the
evaluations, paired comparisons for :func:`replay.reproduce.rules.decide`, the template's fields."""

from __future__ import annotations

import numpy as np

from replay.scoring.significance import holm, t_interval

from .common5 import combine, commands, per_run, rmse_curve, table
from .p003_claims import CLAIMS, OLD
from .p003_plan import GRIDS, POOLED, SETTINGS, rows
from .p003_plots import plots, run_errors
from .render import table as md
from .rules import TEST_NAMES, Comparison, p_text, test_one

P, Q = "printed", "σ_a = 0.03"
EARLY, LATE = slice(20, 40), slice(80, 100)  # steps 21-40 and 81-100 (the prior's transient is over by 20)
NAMES = {
    "a=1.0": "α = 1 (baseline)",
    "pf": "PF (bootstrap, own particle stream)",
    "rough": "PF + roughening K = 0.2",
    "ukf": "UKF (R = mixture covariance)",
    "ekf": "EKF",
    "nofloor": "α = 0.5, no floor (1e−300)",
}
TESTS = {k: c.rule.test for c in CLAIMS for k in (c.rule.decides, c.rule.condition) if k}


def name(r):
    return NAMES.get(r) or f"WF-PF α = {r[2:]}"


def rmse(ev):
    return per_run(ev, 0, "pos_rmse")


def lost(ev):
    return np.array([bool(r.get("lost")) for r in ev.results[0].runs])


def norms(ev):
    """Per-run position-error norms (runs, n), NaN rows for diverged runs."""
    return np.array(
        [
            np.full(len(e["position"]), np.nan)
            if rec.get("diverged")
            else np.linalg.norm(np.asarray(e["position"], float), axis=-1)
            for rec, e in zip(ev.results[0].runs, ev.results[0].errors)
        ]
    )


def growth(ev):
    e = norms(ev)
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.mean(e[:, LATE] ** 2, axis=1)) - np.sqrt(np.mean(e[:, EARLY] ** 2, axis=1))


def distinct(ev):
    return np.array([np.mean(getattr(e, "info", {}).get("distinct", np.nan)) for e in ev.results[0].estimates])


def kurtosis(ratio, eps):
    """Excess kurtosis of the bearing noise (1 − ε) N(0, σ₁²) + ε N(0, (ratio σ₁)²)."""
    return 3 * ((1 - eps) + eps * ratio**4) / ((1 - eps) + eps * ratio**2) ** 2 - 3


def evidence(evs, seeds=POOLED) -> dict:
    """The comparisons the claims draw on (``key -> [Comparison]``), on the runs of ``seeds`` pooled."""

    def get(label, r, fn):
        return np.concatenate([fn(evs[f"{label}|{r}|{k}"]) for k in seeds])

    def cmp(text, label, ra, rb, fn):
        b, lb = get(label, rb, fn), get(label, rb, lost)
        a, la = (np.zeros_like(b), lb) if ra == "zero" else (get(label, ra, fn), get(label, ra, lost))
        return Comparison(text, a, b, lost_a=la, lost_b=lb)

    out = {
        "pf-drift": [
            cmp("0 − PF growth", P, "zero", "pf", growth),
            cmp("UKF growth − PF growth", P, "ukf", "pf", growth),
        ],
        "wf-nodrift": [cmp("WF-PF growth − PF growth", P, "a=0.75", "pf", growth)],
    }
    for key, label in ((P, P), (Q, Q)):
        tail = "" if key == P else "-poor"
        out["wf-better" + tail] = [cmp(f"{label}: WF-PF α = 0.75 − PF", label, "a=0.75", "pf", rmse)]
        out["distinct" + tail] = [
            cmp(f"{label}: α = 1 − α = {a}", label, "a=1.0", f"a={a}", distinct) for a in (0.75, 0.5)
        ]
        out["alpha-rmse" + tail] = out["alpha-lost" + tail] = [
            cmp(f"{label}: α = 0.75 − α = 1", label, "a=0.75", "a=1.0", rmse)
        ]
    e = np.stack([np.abs(np.asarray(x["position"], float)) for x in evs[f"{P}|pf|0"].results[0].errors])
    peak = []
    for j, (axis, paper) in enumerate((("x", 16.0), ("y", 15.0))):
        k = int(np.nanargmax(rmse_curve(e[:, :, j])))
        peak.append(Comparison(f"{axis} at step {k + 1} (m²)", e[:, k, j] ** 2, target=paper**2))
    return {"pf-peak": peak, **out}


def cellof(o, digits=2) -> str:
    """An outcome in a table cell: the estimate, its interval, the (adjusted) p."""
    if o.test == "mcnemar":
        c = o.comparison
        return f"{int(np.sum(c.lost_a))} vs {int(np.sum(c.lost_b))}, p = {p_text(o.p_adj)}"
    s = f"{o.estimate:+.{digits}f} [{o.lo:+.{digits}f}, {o.hi:+.{digits}f}], p = {p_text(o.p_adj)}"
    return f"**{s}**" if o.holds else s


def family(outs, alpha=0.05):
    for o, p in zip(outs, holm([o.p for o in outs])):
        o.p_adj, o.holds = float(p), bool(p < alpha)
    return sum(o.holds for o in outs)


def where(evs, rng) -> tuple[str, dict]:
    """Every setting on seed s: α < 1 against α = 1, the paper's WF-PF 0.75 − PF and roughening against
    α = 1 (auto: paired t, or Wilcoxon and the median's bootstrap interval where a run is lost), lost runs
    (exact McNemar); Holm over each column family. Returns the table and {family: (significant, size)}."""
    cols, lines = {"alpha": [], "paper": [], "rough": [], "lost": []}, []
    for s in SETTINGS:
        ev = {r: evs[f"{s[0]}|{r}|0"] for r in rows(s)}
        pairs = [(f"a={a}", "a=1.0", "alpha") for a in s[4]] + [("a=0.75", "pf", "paper"), ("rough", "a=1.0", "rough")]
        o = {
            (r, b): test_one(Comparison(s[0], rmse(ev[r]), rmse(ev[b]), lost(ev[r]), lost(ev[b])), "auto", rng)
            for r, b, _ in pairs
            if r in ev and b in ev
        }
        for r, b, fam in pairs:
            cols[fam] += [o[(r, b)]] if (r, b) in o else []
        mc = [test_one(o[(f"a={a}", "a=1.0")].comparison, "mcnemar", rng) for a in (0.75, 0.5)]
        cols["lost"] += mc
        counts = "/".join(
            str(int(lost(ev[r]).sum())) if r in ev else "–" for r in ("a=1.0", "a=0.75", "a=0.5", "pf", "rough")
        )
        lines.append((s[0], o, counts, mc))
    n = {k: (family(v), len(v)) for k, v in cols.items()}
    cell = lambda o, k: cellof(o[k]) if k in o else "n/a"
    body = [
        [
            s,
            *[cell(o, (f"a={a}", "a=1.0")) for a in (0.75, 0.5, 0.25)],
            cell(o, ("a=0.75", "pf")),
            cell(o, ("rough", "a=1.0")),
            counts,
            "; ".join(cellof(m) for m in mc),
        ]
        for s, o, counts, mc in lines
    ]
    head = [
        "setting",
        "α = 0.75 − α = 1",
        "α = 0.5 − α = 1",
        "α = 0.25 − α = 1",
        "WF-PF 0.75 − PF",
        "roughening − α = 1",
        "lost α = 1 / 0.75 / 0.5 / PF / rough",
        "McNemar α = 0.75, 0.5 vs α = 1",
    ]
    return md(head, body), n


def pooled(evid, rng) -> tuple[str, dict]:
    """Every comparison of the verdicts (deciding and stated condition) on the pooled seeds, Holm over
    each claim's family as :func:`replay.reproduce.rules.decide` adjusts it; and {claim id: outcomes}."""
    body, by = [], {}
    for c in CLAIMS:
        outs = by[c.id] = [
            test_one(x, c.rule.test, rng) for k in (c.rule.decides, c.rule.condition) if k for x in evid[k]
        ]
        family([o for o in outs if o.test != "interval"], c.rule.alpha)
        n = len(evid[c.rule.decides])
        body += [
            [
                c.id,
                "deciding" if i < n else "stated condition",
                TEST_NAMES[o.test],
                o.text() if o.test == "interval" else f"{o.comparison.name}: {cellof(o)}",
            ]
            for i, o in enumerate(outs)
        ]
    return md(["claim", "comparison", "test", "estimate [95 % interval], Holm-adjusted one-sided p"], body), by


def replication(evs, rng) -> str:
    """Each deciding comparison on each seed alone: estimate [interval], raw p (not deciding)."""
    per, body = [evidence(evs, (k,)) for k in POOLED], []
    for key, test in TESTS.items():
        for i, c in enumerate(per[0][key] if key != "pf-peak" else []):
            outs = [test_one(p[key][i], test, rng) for p in per]
            for o in outs:
                o.p_adj = o.p
            body.append([key, c.name.replace(f"{P}: ", "").replace(f"{Q}: ", ""), *[cellof(o) for o in outs]])
    return md(["evidence", "comparison", *[f"seed s + {k}" for k in POOLED]], body)


def sweep(evs, group) -> str:
    """One result table per setting of ``group`` (mean ± t, median, lost, paired Δ against α = 1) and
    its commands."""
    out, metrics = [], ("pos_rmse", "x_rmse", "y_rmse") if group == P else ("pos_rmse",)
    for s in (s for s in SETTINGS if s[7] == group):
        rs = combine([(f"{s[0]}: {name(r)}", (evs[f"{s[0]}|{r}|0"], 0)) for r in rows(s)], metrics=metrics)
        out += [table(rs, metrics=metrics, base_name="α = 1"), "", "Commands (one per row):", "", commands(rs), ""]
    return "\n".join(out)


def ci(x, digits=2, scale=1.0) -> str:
    m, h = t_interval(np.asarray(x, float) * scale)
    return f"{m:+.{digits}f} ± {h:.{digits}f}" if np.isfinite(h) else "n/a"


def drift(evs) -> str:
    """Growth per filter at the printed setting (pooled seeds) and the peak of RMSE(t) (seed s)."""
    body = []
    for r in ("pf", "a=0.75", "ukf"):
        g = np.concatenate([growth(evs[f"{P}|{r}|{k}"]) for k in POOLED])
        e = np.stack([np.abs(np.asarray(x["position"], float)) for x in evs[f"{P}|{r}|0"].results[0].errors])
        pk = " / ".join(f"{np.nanmax(rmse_curve(e[:, :, j])):.2f}" for j in (0, 1))
        body.append([name(r), pk, ci(g)])
    return md(["filter", "peak of RMSE(t) x / y (m), seed s", f"growth (m), {len(POOLED)} seeds pooled"], body)


def distincts(evs) -> str:
    """Mean distinct particles after resampling, % of N (mean over steps, then runs ± t), seed s."""
    body = []
    for s in SETTINGS:
        cells = [
            ci(distinct(evs[f"{s[0]}|a={a}|0"]), 1, 100 / s[3]).lstrip("+") if a == 1.0 or a in s[4] else "n/a"
            for a in (1.0, 0.75, 0.5, 0.25)
        ]
        body.append([s[0], s[3], *cells])
    return md(["setting", "N", "α = 1", "α = 0.75", "α = 0.5", "α = 0.25"], body)


def tuned(evs, best) -> str:
    """Each baseline at its shared setting and at its grid's best (tuned on the tuning seeds)."""
    shared = {"pf": "pf", "rough": "rough", "ukf": "ukf", "ekf": "ekf", "wf-pf": "a=0.75"}
    body = []
    for (label, f), (v, score, scores) in best.items():
        param = GRIDS[f][0]
        row = lambda ev: (
            f"{ev.rows[0]['pos_rmse']:.2f} ± {ev.rows[0]['pos_rmse_ci95']:.2f} "
            f"(median {ev.rows[0]['pos_rmse_median']:.2f}, lost {ev.rows[0]['lost']})"
        )
        edge = " (grid edge)" if v in (min(scores), max(scores)) and len(scores) > 1 else ""
        body.append(
            [
                label,
                f,
                param,
                ", ".join(f"{g:g}: {x:.2f}" for g, x in scores.items()),
                f"{v:g}{edge}",
                row(evs[f"{label}|{shared[f]}|0"]),
                row(evs[f"tuned|{label}|{f}"]),
            ]
        )
    return md(
        [
            "setting",
            "filter",
            "tuned parameter",
            "grid: tuning mean RMSE (m)",
            "chosen",
            "shared setting: pos_rmse (m), seed s",
            "tuned: pos_rmse (m), seed s",
        ],
        body,
    )


def poor(evs, rng) -> str:
    """The impoverished setting in numbers: lost runs of each row (seed s) and α = 0.5 against α = 1
    on the pooled seeds (not the paper's α: not deciding)."""
    get = lambda r, fn: np.concatenate([fn(evs[f"{Q}|{r}|{k}"]) for k in POOLED])
    c = Comparison("α = 0.5 − α = 1", get("a=0.5", rmse), get("a=1.0", rmse), get("a=0.5", lost), get("a=1.0", lost))
    o, m = test_one(c, "auto", rng), test_one(c, "mcnemar", rng)
    o.p_adj, m.p_adj = o.p, m.p
    seed_s = ", ".join(
        f"{name(r)} {int(lost(evs[f'{Q}|{r}|0']).sum())}" for r in rows(next(s for s in SETTINGS if s[0] == Q))
    )
    kept = ", ".join(f"α = {a}: {np.nanmean(get(f'a={a}', distinct)):.1f}" for a in (1.0, 0.75, 0.5))
    tuned = ", ".join(f"{f} {evs[f'tuned|{Q}|{f}'].rows[0]['lost']}" for f in GRIDS)
    return (
        f"lost runs (of {len(lost(evs[f'{Q}|a=1.0|0']))}) at seed s: {seed_s}; tuned: {tuned}. "
        f"α = 0.5 against α = 1, {len(c.a)} pooled runs: median Δ {cellof(o)}; lost {cellof(m)}. "
        f"Distinct particles after resampling (of N = 100, pooled): {kept}"
    )


def fields(evs, best, runs, doc, verdicts, evid) -> dict:
    """Every placeholder of ``replay/papers/003.md`` but the verdicts and the command."""
    rng = np.random.default_rng(0)
    where_table, n = where(evs, rng)
    pooled_table, outs = pooled(evid, rng)
    ev = {r: evs[f"{P}|{r}|0"] for r in ("pf", "a=0.75", "ukf")}
    figs = plots(ev["pf"].t, {name(r): run_errors(e, 0) for r, e in ev.items()}, doc, "printed setting")
    relabel = [
        f"* {v.claim.words}: {OLD[v.claim.id]} → **{v.label}** (" + "; ".join(o.text() for o in outs[v.claim.id]) + ")"
        for v in verdicts
    ]
    return {
        "runs": runs,
        "seeds": len(POOLED),
        "k_printed": f"{kurtosis(2, 0.75):.2f}",
        "k_strong": f"{kurtosis(10, 0.1):.1f}",
        "drift": drift(evs),
        "plots": "\n".join(figs),
        "distinct": distincts(evs),
        "where": where_table,
        "pooled": pooled_table,
        "relabel": "\n".join(relabel),
        "replication": replication(evs, rng),
        "tuned": tuned(evs, best),
        "poor": poor(evs, rng),
        **{f"n_{k}": f"{a} of {b}" for k, (a, b) in n.items()},
        **{f"t_{g}": sweep(evs, g) for g in (P, "N", "Q", "contrast", "mismatch")},
    }
