"""replay.scoring.significance against scipy.stats and hand computations."""
import numpy as np
import pytest
from scipy import stats

from replay.scoring import significance as sig

ALTS = ("less", "greater", "two-sided")


def test_holm_matches_a_hand_computation():
    # p sorted: 0.01 (x4 = 0.04), 0.02 (x3 = 0.06), 0.03 (x2 = 0.06), 0.04 (x1 = 0.04 -> monotone 0.06)
    assert np.allclose(sig.holm([0.03, 0.01, 0.04, 0.02]), [0.06, 0.04, 0.06, 0.06])
    # capped at 1, NaN counted as 1, order kept
    assert np.allclose(sig.holm([0.5, np.nan, 0.001]), [1.0, 1.0, 0.003])
    assert np.allclose(sig.holm([0.2]), [0.2])


@pytest.mark.parametrize("n", [3, 8, 13, 30, 50, 51, 200])
@pytest.mark.parametrize("alt", ALTS)
def test_wilcoxon_matches_scipy(n, alt):
    rng = np.random.default_rng(n)
    a = rng.normal(size=n)
    b = a + rng.normal(0.2, 1.0, size=n)
    w, p = sig.wilcoxon_paired(a, b, alt)
    ref = stats.wilcoxon(a, b, alternative=alt)
    assert w == ref.statistic
    assert p == pytest.approx(ref.pvalue, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("alt", ALTS)
def test_wilcoxon_with_ties_and_zeros_matches_scipy_exact_permutation(alt):
    d = np.array([1, 2, 2, 4, 5, -6, 7, 0.0, 3, 3, -2])
    w, p = sig.wilcoxon_paired(d, np.zeros_like(d), alt)
    ref = stats.wilcoxon(d, alternative=alt)  # n <= 13 with ties: scipy enumerates every sign pattern
    assert (w, p) == pytest.approx((ref.statistic, ref.pvalue), rel=1e-12)


def test_wilcoxon_drops_nan_pairs():
    a = np.array([1.0, 2.0, np.nan, 4.0, 0.5, 3.0])
    b = np.array([2.0, 3.5, 1.0, 6.0, 0.7, 2.0])
    ok = np.isfinite(a)
    assert sig.wilcoxon_paired(a, b)[1] == pytest.approx(stats.wilcoxon(a[ok], b[ok], alternative="less").pvalue)


@pytest.mark.parametrize("alt", ALTS)
def test_paired_t_matches_scipy(alt):
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=12), rng.normal(0.5, 1, size=12)
    t, p = sig.paired_t(a, b, alt)
    ref = stats.ttest_rel(a, b, alternative=alt)
    assert (t, p) == pytest.approx((ref.statistic, ref.pvalue), rel=1e-12)


def test_t_interval_matches_scipy():
    x = np.array([1.0, 2.5, 2.0, 3.5, 0.5, np.nan])
    m, h = sig.t_interval(x)
    lo, hi = stats.t.interval(0.95, 4, loc=np.nanmean(x), scale=stats.sem(x[:5]))
    assert m == pytest.approx(1.9) and (m - h, m + h) == pytest.approx((lo, hi), rel=1e-12)
    assert np.isnan(sig.t_interval([1.0])[1])


@pytest.mark.parametrize("table", [(0, 10, 5, 10), (3, 20, 9, 20), (7, 15, 2, 30), (10, 10, 0, 10), (1, 4, 1, 4)])
@pytest.mark.parametrize("alt", ALTS)
def test_fisher_matches_scipy(table, alt):
    k_a, n_a, k_b, n_b = table
    ref = stats.fisher_exact([[k_a, n_a - k_a], [k_b, n_b - k_b]], alternative=alt).pvalue
    assert sig.fisher_exact_lost(k_a, n_a, k_b, n_b, alt) == pytest.approx(ref, rel=1e-10)


@pytest.mark.parametrize("alt", ALTS)
def test_mcnemar_is_the_binomial_test_of_the_discordant_runs(alt):
    a = np.array([1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 1, 1], bool)
    b = np.array([1, 1, 1, 0, 0, 1, 1, 1, 0, 1, 1, 0], bool)
    only_a, only_b, p = sig.mcnemar_exact(a, b, alt)
    assert (only_a, only_b) == (2, 6)
    assert p == pytest.approx(stats.binomtest(2, 8, 0.5, alternative=alt).pvalue, rel=1e-12)


def test_median_bootstrap_interval_holds_the_median_and_is_reproducible():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=40), rng.normal(size=40)
    m, lo, hi = sig.median_diff_ci(a, b, np.random.default_rng(5))
    assert m == pytest.approx(np.median(a - b)) and lo < m < hi
    assert sig.median_diff_ci(a, b, np.random.default_rng(5)) == (m, lo, hi)
    ref = stats.bootstrap(((a - b),), np.median, method="percentile", n_resamples=4000,
                          random_state=np.random.default_rng(1)).confidence_interval
    assert lo == pytest.approx(ref.low, abs=0.15) and hi == pytest.approx(ref.high, abs=0.15)


def test_bimodal_chooses_the_rank_test():
    assert sig.choose_test([False, False], [False, False]) == "t"
    assert sig.choose_test([False, True], [False, False]) == "wilcoxon"
    assert sig.choose_test(None, None) == "t"
