"""The scoring's shortcuts give the numbers of the code they replace, bit for bit.

* :func:`replay.scoring.metrics.lstsq_rows` (one gufunc call) and ``np.linalg.lstsq`` row by row
  (the NEES of a run whose position covariance is singular somewhere);
* :func:`replay.scoring.metrics.chi2_ppf` and :func:`replay.scoring.scorer.t_ppf` (scipy.special) and
  ``scipy.stats.chi2.ppf`` / ``scipy.stats.t.ppf``, which the scoring modules no longer
  import (0.5-1 s at the start of every campaign).
"""
import subprocess
import sys

import numpy as np
import pytest

from replay.scoring import metrics, scorer


def _stacks(d: int, k: int = 400):
    rng = np.random.default_rng(d)
    A = rng.normal(size=(k, d, d))
    A = A @ A.transpose(0, 2, 1)
    A[::3, -1] = A[::3, 0]  # rank-deficient rows
    A[1::5, :, -1] = A[1::5, -1, :] = 0.0  # a zero variance
    A[::7] = 0.0  # all zero
    A[2::11] *= 1e-12  # tiny
    return A, rng.normal(size=(k, d)) * rng.choice([1e-6, 1.0, 1e6], size=(k, 1))


@pytest.mark.parametrize("d", [1, 2, 3, 6])
def test_lstsq_rows_is_lstsq_of_each_row_bit_for_bit(d):
    A, b = _stacks(d)
    expected = np.stack([np.linalg.lstsq(a, v, rcond=None)[0] for a, v in zip(A, b)])
    got = metrics.lstsq_rows(A, b)
    assert got.shape == expected.shape == (len(A), d) and got.dtype == np.float64
    assert np.array_equal(got.view(np.uint64), expected.view(np.uint64))


def test_lstsq_rows_of_nothing_and_of_a_non_finite_matrix():
    assert metrics.lstsq_rows(np.zeros((0, 3, 3)), np.zeros((0, 3))).shape == (0, 3)
    with pytest.raises(np.linalg.LinAlgError, match="SVD did not converge"):
        metrics.lstsq_rows(np.array([[[np.inf, 1.0], [1.0, 1.0]]]), np.array([[1.0, 2.0]]))


def test_nees_with_a_singular_covariance_is_least_squares_on_every_row():
    A, e = _stacks(3, 200)
    A[5] = np.eye(3)  # solve() refuses the stack: every row goes through least squares
    e[7] = np.nan  # not scored
    out = metrics.nees(e, A)
    ok = np.isfinite(e).all(axis=1)
    u = np.stack([np.linalg.lstsq(a, v, rcond=None)[0] for a, v in zip(A[ok], e[ok])])
    assert np.isnan(out[7]) and np.array_equal(out[ok], np.einsum("...i,...i->...", e[ok], u))


DOFS = np.r_[np.arange(1, 1001), np.linspace(0.05, 3000.5, 1201), 3.0 * np.arange(1, 20001, 13), 1e6]


@pytest.mark.parametrize("q", [0.025, 0.975, 0.5, 1e-9])
def test_quantiles_are_scipy_stats_bit_for_bit(q):
    from scipy import stats

    assert np.array_equal(metrics.chi2_ppf(q, DOFS), stats.chi2.ppf(q, DOFS))
    assert np.array_equal(scorer.t_ppf(q, DOFS), stats.t.ppf(q, DOFS))
    for df in (1, 2.0, 49, 150.0, np.int64(75)):  # scalars stay numpy scalars
        for ours, theirs in ((metrics.chi2_ppf(q, df), stats.chi2.ppf(q, df)),
                             (scorer.t_ppf(q, df), stats.t.ppf(q, df))):
            assert ours == theirs and type(ours) is type(theirs)
    for df in (0, -1.0, np.nan):
        assert np.isnan(metrics.chi2_ppf(q, df)) and np.isnan(stats.chi2.ppf(q, df))
        assert np.isnan(scorer.t_ppf(q, df)) and np.isnan(stats.t.ppf(q, df))


def test_ci95_and_consistency_band_known_values():
    # t(0.975, 3) = 3.18245; the band of 50 runs of a 3-D NEES is the example campaign's [2.35969, 3.71601]
    assert scorer.ci95([1.0, 2.0, 3.0, 4.0]) == pytest.approx(3.1824463 * np.std([1, 2, 3, 4], ddof=1) / 2)
    lo, hi = metrics.chi2_band(3, 50)
    assert (lo, hi) == (pytest.approx(2.359690, abs=1e-6), pytest.approx(3.716009, abs=1e-6))


def test_campaign_modules_do_not_import_scipy_stats():
    code = ("import sys\n"
            "import replay.campaign.execute, replay.scoring.summary, replay.scoring.metrics, replay.scoring.scorer\n"
            "from replay.scoring import metrics, scorer\n"
            "metrics.chi2_band(3, 10); scorer.ci95([1.0, 2.0])\n"
            "print('scipy.stats' in sys.modules)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"


def test_runs_equal_up_to_rounding_have_an_interval_of_exactly_zero():
    """Issue 40 item 4: a deterministic filter's runs computed in one batch differ in their last bits
    (1.3053891220575129 and its neighbours): the interval is 0, not 1.7e-16; a real spread is kept."""
    from replay.scoring import significance
    from replay.scoring.scorer import aggregate, ci95, deterministic

    v = 1.3053891220575129
    ulps = np.array([v, np.nextafter(v, 2), v, np.nextafter(v, 0), v])
    assert np.ptp(ulps) > 0 and deterministic(ulps) and ci95(ulps) == 0.0
    assert significance.t_interval(ulps) == (pytest.approx(v, rel=1e-15), 0.0)
    assert ci95([v] * 4) == 0.0 and ci95([0.0, 0.0]) == 0.0
    spread = np.array([v, v * (1 + 1e-9)])  # above the 1e-12 bound: an interval
    assert not deterministic(spread) and ci95(spread) > 0
    assert ci95(spread) == pytest.approx(12.706204736174707 * np.std(spread, ddof=1) / np.sqrt(2), rel=1e-12)
    runs = [{"diverged": False, "pos_rmse": x, "us_per_step": 1.0, "scored": 1, "masked": 0} for x in ulps]
    agg = aggregate(runs)
    assert agg["pos_rmse_ci95"] == 0.0 and agg["pos_rmse"] == pytest.approx(v, rel=1e-15)


def test_the_report_prints_a_zero_interval_as_zero_and_two_deterministic_rows_as_exact():
    from replay.outputs import report_tables as rt

    assert rt.pm(1.3053891220575129, 0.0) == "1.31 ± 0"
    assert rt.pm(1.3053891220575129, 1.7e-16) == "1.3053891220575129 ± 0.0000000000000002"  # the text
    a = {"pos_rmse": 1.3, "pos_rmse_ci95": 0.0}
    assert rt._apart(a, {"pos_rmse": 1.4, "pos_rmse_ci95": 0.0}) == "both deterministic (interval 0): the difference is exact"
    assert rt._apart(a, {"pos_rmse": 1.4, "pos_rmse_ci95": 0.05}) == "intervals disjoint"
    assert rt._apart(a, {"pos_rmse": 1.4, "pos_rmse_ci95": 0.2}) == "intervals overlap"
