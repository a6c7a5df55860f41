"""Significance tests and intervals for comparing filters over Monte Carlo runs (numpy and scipy only).

Every comparison here is **paired**: ``a[i]`` and ``b[i]`` are the same run (the
same measurements, common random numbers) under two filters or settings, and a
pair with a NaN is left out. One-sided tests take ``alternative="less"`` for the
claim "a is smaller than b" (a lower error), the default.

* :func:`holm` — Holm's step-down adjustment of a family of p-values;
* :func:`paired_t` — paired t-test; :func:`t_interval` — mean and 95 % Student-t half-width
  (what the tables print);
* :func:`wilcoxon_paired` — Wilcoxon signed-rank test (zeros dropped, Wilcoxon's rule),
  exact distribution (ties included, by the ranks' sums) up to 50 pairs, the normal
  approximation with the tie correction above;
* :func:`median_diff_ci` — the median of the paired differences and its percentile
  bootstrap interval (the generator passed explicitly: reproducible);
* :func:`mcnemar_exact` — exact McNemar test on paired lost flags (binomial on the
  discordant runs); :func:`fisher_exact_lost` — Fisher's exact test on two lost counts;
* :func:`bimodal` — whether lost runs make per-run errors bimodal (any lost run in either
  arm): then a verdict uses the rank test and the median (:func:`choose_test`), not a t-test.

Each function equals its ``scipy.stats`` counterpart (``tests/test_significance.py``).
"""

from __future__ import annotations

import math

import numpy as np
from replay.scoring.scorer import deterministic, t_ppf

ALTERNATIVES = ("less", "greater", "two-sided")


def _scipy():
    """``(scipy.stats, scipy.special)``, imported at the first test: every ``replay`` command imports this
    module (the tables' intervals, :func:`t_interval`, need only ``t_ppf``) and scipy.stats costs about
    0.3 s of a command's start (``python -X importtime``), for the tests of reproductions and ``tune``."""
    # lazy: start-up, scipy.stats measured ~0.3 s on `replay eval` beside what the intervals import
    from scipy import special, stats  # noqa: PLC0415

    return stats, special


def _alt(alternative: str) -> str:
    if alternative not in ALTERNATIVES:
        raise ValueError(f"alternative {alternative!r}: one of {', '.join(ALTERNATIVES)}")
    return alternative


def pairs(a, b) -> tuple[np.ndarray, np.ndarray]:
    """``a``, ``b`` as float arrays of one length with the pairs holding a NaN removed (an infinite
    value stays: a diverged run, the worst error, ranks last; two infinities make a NaN pair)."""
    a, b = np.asarray(a, float).ravel(), np.asarray(b, float).ravel()
    if a.shape != b.shape:
        raise ValueError(f"paired samples of different lengths ({len(a)} and {len(b)})")
    with np.errstate(invalid="ignore"):
        ok = ~np.isnan(a) & ~np.isnan(b) & ~np.isnan(a - b)
    return a[ok], b[ok]


def holm(pvalues) -> np.ndarray:
    """Holm-adjusted p-values (same order): sorted p(1) <= ... <= p(m), adjusted
    max over j <= i of (m - j + 1) p(j), capped at 1. A NaN p-value counts as 1."""
    p = np.asarray(pvalues, float).ravel()
    p = np.where(np.isfinite(p), p, 1.0)
    m = len(p)
    order = np.argsort(p, kind="stable")
    adj = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    out = np.empty(m)
    out[order] = adj
    return out


def t_interval(x, level: float = 0.95) -> tuple[float, float]:
    """Mean of ``x`` (NaN left out) and the half-width of its Student-t interval (NaN below 2 values;
    exactly 0 for values equal up to rounding, :func:`replay.scoring.scorer.deterministic`)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return float("nan"), float("nan")
    if len(x) < 2:
        return float(x.mean()), float("nan")

    if deterministic(x):  # one value up to rounding: an interval of exactly 0
        return float(x.mean()), 0.0
    half = t_ppf(0.5 + level / 2, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x))
    return float(x.mean()), float(half)


def _p_from_t(t: float, df: int, alternative: str) -> float:
    stats, _ = _scipy()
    if alternative == "less":
        return float(stats.t.cdf(t, df))
    if alternative == "greater":
        return float(stats.t.sf(t, df))
    return float(2 * stats.t.sf(abs(t), df))


def paired_t(a, b, alternative: str = "less") -> tuple[float, float]:
    """Paired t-test of a - b: ``(t, p)`` (NaN with fewer than 2 pairs; p 1 or 0 when every
    difference is equal, by its sign)."""
    a, b = pairs(a, b)
    d = a - b
    alternative = _alt(alternative)
    if len(d) < 2 or not np.isfinite(d).all():
        return float("nan"), float("nan")
    sd = d.std(ddof=1)
    if sd == 0:
        t = math.copysign(math.inf, d[0]) if d[0] != 0 else 0.0
        if t == 0:
            return 0.0, 1.0
        return t, _p_from_t(t, len(d) - 1, alternative)
    t = float(d.mean() / (sd / math.sqrt(len(d))))
    return t, _p_from_t(t, len(d) - 1, alternative)


def _ranks(x: np.ndarray) -> np.ndarray:
    return _scipy()[0].rankdata(x)  # average ranks of ties


def _exact_signed_rank_cdf(ranks: np.ndarray) -> tuple[np.ndarray, int]:
    """Counts of every value of 2·W+ over the 2^n sign patterns (ranks: multiples of 0.5)."""
    r2 = np.rint(2 * ranks).astype(np.int64)
    total = int(r2.sum())
    counts = np.zeros(total + 1, dtype=object)  # exact integers (2^50 overflows float precision)
    counts[0] = 1
    for r in r2:
        counts[r:] = counts[r:] + counts[: total + 1 - r]
    return counts, total


def wilcoxon_paired(a, b, alternative: str = "less") -> tuple[float, float]:
    """Wilcoxon signed-rank test of the paired differences a - b: ``(W, p)``; W is W+, the sum of
    the ranks of the positive differences, for a one-sided test and min(W+, W-) for a two-sided
    one (scipy's statistic). Zero differences are dropped; exact up to 50 non-zero pairs
    (conditional on tied ranks), normal approximation with the tie correction above.
    NaN p with no non-zero pair."""
    a, b = pairs(a, b)
    alternative = _alt(alternative)
    d = a - b
    d = d[d != 0]
    n = len(d)
    if n == 0:
        return float("nan"), float("nan")
    r = _ranks(np.abs(d))
    w = float(r[d > 0].sum())
    if n <= 50:
        counts, total = _exact_signed_rank_cdf(r)
        k = int(round(2 * w))
        allp = 2**n
        lo = int(sum(counts[: k + 1])) / allp  # P(W+ <= w)
        hi = int(sum(counts[k:])) / allp  # P(W+ >= w)
        p = {"less": lo, "greater": hi, "two-sided": min(1.0, 2 * min(lo, hi))}[alternative]
        return _w_stat(w, total / 2, alternative), float(p)
    mean = n * (n + 1) / 4
    _, tie = np.unique(r, return_counts=True)
    var = n * (n + 1) * (2 * n + 1) / 24 - (tie**3 - tie).sum() / 48
    z = (w - mean) / math.sqrt(var)
    stats, _ = _scipy()
    p = {"less": stats.norm.cdf(z), "greater": stats.norm.sf(z), "two-sided": 2 * stats.norm.sf(abs(z))}[alternative]
    return _w_stat(w, n * (n + 1) / 2, alternative), float(min(1.0, p))


def _w_stat(w: float, total: float, alternative: str) -> float:
    """scipy's reported statistic: W+ one-sided, min(W+, W-) two-sided."""
    return min(w, total - w) if alternative == "two-sided" else w


def median_diff_ci(
    a, b, rng: np.random.Generator, n_boot: int = 4000, level: float = 0.95
) -> tuple[float, float, float]:
    """Median of the paired differences a - b and its percentile bootstrap interval
    ``(median, lo, hi)`` (runs resampled with replacement, ``n_boot`` times, from ``rng``)."""
    a, b = pairs(a, b)
    d = a - b
    if len(d) == 0:
        return float("nan"), float("nan"), float("nan")
    idx = rng.integers(0, len(d), size=(n_boot, len(d)))
    meds = np.median(d[idx], axis=1)
    lo, hi = np.quantile(meds, [0.5 - level / 2, 0.5 + level / 2])
    return float(np.median(d)), float(lo), float(hi)


def _binom_p(k: int, n: int, alternative: str) -> float:
    """Exact binomial test of k successes in n at 1/2."""
    if n == 0:
        return 1.0
    stats, _ = _scipy()
    if alternative == "less":
        return float(stats.binom.cdf(k, n, 0.5))
    if alternative == "greater":
        return float(stats.binom.sf(k - 1, n, 0.5))
    return float(min(1.0, 2 * stats.binom.cdf(min(k, n - k), n, 0.5)))


def mcnemar_exact(lost_a, lost_b, alternative: str = "less") -> tuple[int, int, float]:
    """Exact McNemar test of paired lost flags: ``(only_a, only_b, p)``, the runs lost by a alone
    and by b alone, and the binomial p of only_a among the discordant runs ("less": a loses
    fewer runs than b)."""
    a, b = np.asarray(lost_a, bool).ravel(), np.asarray(lost_b, bool).ravel()
    if a.shape != b.shape:
        raise ValueError(f"paired lost flags of different lengths ({len(a)} and {len(b)})")
    only_a, only_b = int((a & ~b).sum()), int((b & ~a).sum())
    return only_a, only_b, _binom_p(only_a, only_a + only_b, _alt(alternative))


def fisher_exact_lost(k_a: int, n_a: int, k_b: int, n_b: int, alternative: str = "less") -> float:
    """Fisher's exact test of k_a lost of n_a runs against k_b of n_b (unpaired): the
    hypergeometric p ("less": a loses a smaller share than b; two-sided: every table no more
    probable than the observed one, scipy's rule)."""
    alternative = _alt(alternative)
    for name, k, n in (("a", k_a, n_a), ("b", k_b, n_b)):
        if not (0 <= k <= n):
            raise ValueError(f"lost count of {name}: {k} of {n} runs")
    lost, total = k_a + k_b, n_a + n_b
    lo, hi = max(0, lost - n_b), min(n_a, lost)
    ks = np.arange(lo, hi + 1)
    _, special = _scipy()
    logp = (
        special.gammaln(n_a + 1)
        - special.gammaln(ks + 1)
        - special.gammaln(n_a - ks + 1)
        + special.gammaln(n_b + 1)
        - special.gammaln(lost - ks + 1)
        - special.gammaln(n_b - lost + ks + 1)
        - special.gammaln(total + 1)
        + special.gammaln(lost + 1)
        + special.gammaln(total - lost + 1)
    )
    pk = np.exp(logp)
    if alternative == "less":
        p = pk[ks <= k_a].sum()
    elif alternative == "greater":
        p = pk[ks >= k_a].sum()
    else:
        p = pk[pk <= pk[ks == k_a][0] * (1 + 1e-7)].sum()
    return float(min(1.0, p))


def bimodal(lost_a, lost_b) -> bool:
    """True when either arm lost a run: per-run errors then mix tracked and lost runs."""
    return bool(np.any(np.asarray(lost_a, bool)) or np.any(np.asarray(lost_b, bool)))


def choose_test(lost_a=None, lost_b=None) -> str:
    """``"wilcoxon"`` (rank test, median) when lost runs make the errors bimodal, else ``"t"``."""
    la = [] if lost_a is None else lost_a
    lb = [] if lost_b is None else lost_b
    return "wilcoxon" if bimodal(la, lb) else "t"
