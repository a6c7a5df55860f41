"""The tables of ``report.html``: the summary, each section's leaderboard and its paired comparisons.

Numbers are rounded to three significant digits (:func:`num`), a mean carries its 95 %
interval (``2.40 ± 0.34``), ANEES/ANIS carry their flag (``collapsed`` instead of a
meaningless number), ``lost`` reads ``k/N`` (``*``: lost runs dominate the mean). A paired
difference smaller than :data:`TIE` (in the metric's unit) is a tie: no "wins" on rounding
noise (two filters that are the same on a linear model differ by 1e-16 m).
"""

from __future__ import annotations

import html
import math

import numpy as np

from replay.scoring import gap, summary
from replay.scoring.marks import marks
from replay.outputs.palette import Palette

TIE = 1e-6  # paired differences below this (m) are ties
UNITS = {"pos_rmse": "m", "ate": "m", "final_err": "m", "drift_pct": "%"}


def _f(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _decimals(v: float, sig: int = 3) -> int:
    return max(0, sig - 1 - math.floor(math.log10(abs(v)))) if v and math.isfinite(v) else 0


def num(v, sig: int = 3) -> str:
    """``v`` to ``sig`` significant digits, without an exponent between 1e-3 and 1e5; ``–`` if missing."""
    v = _f(v)
    if not math.isfinite(v):
        return "–"
    if v == 0:
        return "0"
    if not 1e-3 <= abs(v) < 1e5:
        return f"{v:.{sig - 1}e}"
    return f"{v:.{_decimals(v, sig)}f}"


def count(v) -> str:
    """A count: ``20``, not ``20.0``."""
    v = _f(v)
    return str(int(v)) if math.isfinite(v) else "–"


def pm(v, ci, sig: int = 3) -> str:
    """``mean ± half-width`` with both rounded to the same decimals (the mean's 3 significant digits)."""
    v, ci = _f(v), _f(ci)
    if not math.isfinite(v):
        return "–"
    if not math.isfinite(ci):
        return num(v, sig)
    if ci == 0:  # deterministic runs (replay.scoring.scorer.deterministic): an interval of exactly 0
        return f"{num(v, sig)} ± 0"
    if not 1e-3 <= abs(v) < 1e5:
        return f"{num(v, sig)} ± {num(ci, 2)}"
    dec = max(_decimals(v, sig), _decimals(ci, 1) if 0 < ci < 10 ** -_decimals(v, sig) else 0)
    return f"{v:.{dec}f} ± {ci:.{dec}f}"


def diff(d, ci) -> str:
    """A paired difference and its 95 % half-width to the half-width's 2 significant digits;
    a tie (both below :data:`TIE`) reads ``|a − b| < 1e-06``."""
    d, ci = _f(d), _f(ci)
    if not math.isfinite(d):
        return "–"
    if abs(d) < TIE and (not math.isfinite(ci) or ci < TIE):
        return f"|a − b| < {TIE:g}"
    if not math.isfinite(ci) or not 1e-3 <= ci < 1e5:
        return pm(d, ci)
    dec = _decimals(ci, 2)
    return f"{d:+.{dec}f} ± {ci:.{dec}f}"


def _apart(best, nxt) -> str:
    """Whether two rows' intervals overlap; two deterministic rows (intervals of 0) have no interval
    to compare: their difference is exact."""
    cb, cn = _f(best.get("pos_rmse_ci95")), _f(nxt.get("pos_rmse_ci95"))
    if cb == 0 and cn == 0:
        return "both deterministic (interval 0): the difference is exact"
    lo, hi = _f(best["pos_rmse"]) + cb, _f(nxt["pos_rmse"]) - cn
    return "intervals " + ("disjoint" if lo < hi else "overlap")


def consistency(row, prefix: str) -> str:
    """ANEES/ANIS with its flag: ``2.10``, ``10.0 optimistic``, ``collapsed``."""
    flag = row.get(f"{prefix}_flag") or ""
    if flag == "collapsed":
        return "collapsed"
    v = num(row.get(prefix))
    return v if flag in ("", "consistent") or v == "–" else f"{v} {flag}"


def swatch(colour: str) -> str:
    return f'<span class="sw" style="background:{colour}"></span>'


# (header, cell) of the leaderboard table
COLUMNS = [
    ("configuration", lambda r: r.get("label", r.get("filter", ""))),
    ("runs", lambda r: count(r.get("runs"))),
    ("diverged", lambda r: count(r.get("diverged"))),
    ("lost", summary.lost_cell),
    ("position RMSE (m)", lambda r: pm(r.get("pos_rmse"), r.get("pos_rmse_ci95"))),
    ("median RMSE (m)", lambda r: num(r.get("pos_rmse_median"))),
    ("ATE (m)", lambda r: pm(r.get("ate"), r.get("ate_ci95"))),
    ("final error (m)", lambda r: pm(r.get("final_err"), r.get("final_err_ci95"))),
    ("drift (%)", lambda r: pm(r.get("drift_pct"), r.get("drift_pct_ci95"))),
    ("gap to the best smoother", gap.cell),
    ("ANEES", lambda r: consistency(r, "anees")),
    ("ANIS", lambda r: consistency(r, "anis")),
    ("µs/step", lambda r: num(r.get("us_per_step"))),
]


def leaderboard(rows, pal: Palette) -> str:
    """One section's leaderboard: rounded, with flags; the lowest position RMSE in bold."""
    ranked = (r for r in rows if math.isfinite(_f(r.get("pos_rmse"))) and not marks(r))  # marks: never the best
    best = min(ranked, key=lambda r: _f(r["pos_rmse"]), default=None)
    cols = [(h, fn) for h, fn in COLUMNS if any(fn(r) not in ("–", "", "nan") for r in rows)]
    out = ["<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h, _ in cols) + "</tr>"]
    for r in rows:
        cells = []
        for i, (h, fn) in enumerate(cols):
            text = html.escape(str(fn(r)))
            if i == 0:
                text = swatch(pal.colour(r.get("label"))) + text
            cls = ' class="best"' if r is best and h == "position RMSE (m)" else ""
            cells.append(f"<td{cls}>{text}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    return "\n".join(out + ["</table>"])


def verdict(diff, ci, a: str, b: str, unit: str = "m") -> str:
    """What a paired difference a - b with 95 % half-width ``ci`` says."""
    diff, ci = _f(diff), _f(ci)
    if not math.isfinite(diff):
        return "no common runs"
    if abs(diff) < TIE and (not math.isfinite(ci) or ci < TIE):
        return f"tie (|a − b| < {TIE:g} {unit})"
    if not math.isfinite(ci) or abs(diff) <= ci:
        return "no significant difference"
    return f"{a if diff < 0 else b} lower"


def wins(sec, a: str, b: str, metric: str):
    """(a lower, b lower, ties) over the common runs, ties below :data:`TIE`; None if unknown."""
    ma, mb = sec.metrics.get(a), sec.metrics.get(b)
    if not ma or not mb:
        return None
    d = np.array([_f(ma[r].get(metric)) - _f(mb[r].get(metric)) for r in sorted(set(ma) & set(mb))])
    d = d[np.isfinite(d)]
    if not len(d):
        return None
    return int((d <= -TIE).sum()), int((d >= TIE).sum()), int((abs(d) < TIE).sum())


def paired(sec, pal: Palette) -> str:
    """The paired comparisons (common random numbers) of a section, with a verdict and run
    counts, in a ``<details>`` element whose summary counts ties and significant differences."""
    head = ["a", "b", "metric", "runs", "mean of a − b, 95 % interval", "verdict", "runs a lower / b lower / tied"]
    says = [verdict(p.get("diff"), p.get("diff_ci95"), p["a"], p["b"]) for p in sec.paired]
    tally = (
        f"{len(says)} comparisons: {sum(v.endswith(' lower') for v in says)} significant, "
        f"{sum(v.startswith('tie') for v in says)} ties (|a − b| < {TIE:g}), "
        f"{sum(v == 'no significant difference' for v in says)} not significant"
    )
    out = [
        f"<details><summary>Paired comparisons on the same runs (common random numbers): {tally}</summary>",
        "<table><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>",
    ]
    for p in sec.paired:
        unit = UNITS.get(p.get("metric"), "")
        w = wins(sec, p["a"], p["b"], p.get("metric"))
        cells = [
            swatch(pal.colour(p["a"])) + html.escape(p["a"]),
            swatch(pal.colour(p["b"])) + html.escape(p["b"]),
            html.escape(f"{p.get('metric')} ({unit})" if unit else str(p.get("metric"))),
            count(p.get("n")),
            html.escape(diff(p.get("diff"), p.get("diff_ci95"))),
            html.escape(verdict(p.get("diff"), p.get("diff_ci95"), p["a"], p["b"], unit or "")),
            "/".join(map(str, w)) if w else "–",
        ]
        out.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return "\n".join(out + ["</table></details>"])


def _pair(sec, a: str, b: str):
    for p in sec.paired:
        if p.get("metric") == "pos_rmse" and {p["a"], p["b"]} == {a, b}:
            sign = 1 if p["a"] == a else -1
            return sign * _f(p["diff"]), _f(p["diff_ci95"])
    return None


def summary_rows(sections) -> list[dict]:
    """Per section: the lowest mean position RMSE with its interval, ties, the runner-up and flags."""
    out = []
    for sec in sections:
        rows = sorted((r for r in sec.rows if math.isfinite(_f(r.get("pos_rmse")))), key=lambda r: _f(r["pos_rmse"]))
        marked = [f"{r['label']}: not ranked: {m}" for r in sec.rows for m in marks(r)]
        rows = [r for r in rows if not marks(r)]  # a row that is not a filter's error is never the best
        if not rows:
            if marked:
                out.append(dict(section=sec.title, best="", ties=[], value="–", runs="–", note="", flags=marked))
            continue
        best = rows[0]
        ties, rest = [], []
        for r in rows[1:]:
            p = _pair(sec, best["label"], r["label"])
            same = (p is not None and abs(p[0]) < TIE and not p[1] >= TIE) or (
                p is None and abs(_f(r["pos_rmse"]) - _f(best["pos_rmse"])) < TIE
            )
            (ties if same else rest).append(r)
        note = ""
        if rest:
            nxt = rest[0]
            p = _pair(sec, best["label"], nxt["label"])
            if p is not None:
                note = (
                    f"next: {nxt['label']} {pm(nxt['pos_rmse'], nxt.get('pos_rmse_ci95'))} m; paired "
                    f"difference {diff(*p)} m: {verdict(*p, best['label'], nxt['label'])}"
                )
            else:
                note = f"next: {nxt['label']} {pm(nxt['pos_rmse'], nxt.get('pos_rmse_ci95'))} m; " + _apart(best, nxt)
        flags = marked + [f"{r['label']}: ANEES collapsed" for r in sec.rows if r.get("anees_flag") == "collapsed"]
        flags += [f"{r['label']}: lost {summary.lost_cell(r)}" for r in sec.rows if _f(r.get("lost")) > 0]
        flags += [f"{r['label']}: {int(_f(r['diverged']))} diverged" for r in sec.rows if _f(r.get("diverged")) > 0]
        out.append(
            {
                "section": sec.title,
                "best": best["label"],
                "ties": [r["label"] for r in ties],
                "value": pm(best["pos_rmse"], best.get("pos_rmse_ci95")),
                "runs": count(best.get("runs")),
                "note": note,
                "flags": flags,
            }
        )
    return out


def summary_table(sections, pal: Palette) -> str:
    head = ["dataset / task", "lowest position RMSE", "mean, 95 % interval (m)", "runs", "compared", "flags"]
    out = ["<table class='summary'><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>"]
    for s in summary_rows(sections):
        best = swatch(pal.colour(s["best"])) + f"<b>{html.escape(s['best'])}</b>" if s["best"] else "none ranked"
        if s["ties"]:
            best += " tied with " + ", ".join(swatch(pal.colour(t)) + html.escape(t) for t in s["ties"])
        cells = [
            html.escape(s["section"]),
            best,
            html.escape(s["value"]),
            s["runs"],
            html.escape(s["note"]),
            html.escape("; ".join(s["flags"])) or "none",
        ]
        out.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return "\n".join(out + ["</table>"])


def legend(pal: Palette) -> str:
    return "<p class='legend'>" + " ".join(f"{swatch(c)}{html.escape(lab)}" for lab, c in pal.items()) + "</p>"
