"""The consistency band of the statistic actually averaged (issue 35 item 5): the mean over runs and
steps of the NEES/NIS against the band of that mean (M·T·d degrees of freedom, corrected for the
time correlation of the NEES), not the one-step band of a single step's average over runs."""
import numpy as np
import pytest
from scipy.stats import chi2

from replay.filters import make_filter
from replay.model import LinearGaussian
from replay.scoring import metrics

REPS, M, T = 200, 5, 100


def _model(r_scale=1.0):
    dt = 1.0
    A = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1.0]])
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    Q = 0.1 * np.kron(np.eye(2), [[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    return LinearGaussian(A, C, Q, np.diag([1.0, 2.0]) * r_scale)


@pytest.fixture(scope="module")
def repetitions():
    """REPS seeded repetitions of M runs of T steps (one batch: the runs are independent), the truth
    drawn from the prior and the model; per-step NEES and NIS of a KF told R and of one told R/10."""
    truth_model = _model()
    rng = np.random.default_rng(2035)
    n = REPS * M
    P0 = np.diag([1.0, 0.5, 1.0, 0.5])
    x = rng.multivariate_normal(np.zeros(4), P0, size=n)
    truth, z = np.empty((n, T, 4)), np.empty((n, T, 2))
    Lq, Lr = np.linalg.cholesky(truth_model.Q), np.linalg.cholesky(truth_model.R)
    for k in range(T):
        x = x @ truth_model.A.T + rng.standard_normal((n, 4)) @ Lq.T
        truth[:, k] = x
        z[:, k] = x @ truth_model.C.T + rng.standard_normal((n, 2)) @ Lr.T
    out = {}
    for name, scale in (("consistent", 1.0), ("overconfident", 0.1)):
        est = make_filter("kf").run_batch(_model(scale), z, np.zeros((n, 4)), np.broadcast_to(P0, (n, 4, 4)).copy(),
                                          [None] * n)
        X, P = np.stack([e.x for e in est]), np.stack([e.P for e in est])
        nees = metrics.nees(X - truth, P).reshape(REPS, M, T)
        nis = np.stack([e.info["nis"] for e in est]).reshape(REPS, M, T)
        out[name] = (nees, nis)
    return out


def _passes(values, dof, prefix):
    return np.array([metrics.consistency(v, dof, prefix)[f"{prefix}_flag"] == "consistent" for v in values])


def test_a_consistent_filter_passes_the_averaged_band_in_95_percent_of_200_repetitions(repetitions):
    nees, nis = repetitions["consistent"]
    nees_pass, nis_pass = _passes(nees, 4, "anees"), _passes(nis, 2, "anis")
    # 0.96 and 0.95 at this seed; over 1000 repetitions 0.947 and 0.97 (the band is a 95 % band of the
    # mean: a consistent filter fails it about 1 time in 20, the NEES a little more often)
    assert nees_pass.mean() >= 0.95 and nis_pass.mean() >= 0.95, (nees_pass.mean(), nis_pass.mean())


def test_an_overconfident_filter_fails_it(repetitions):
    nees, nis = repetitions["overconfident"]  # told R / 10
    assert not _passes(nees, 4, "anees").any() and not _passes(nis, 2, "anis").any()


def test_the_one_step_band_would_have_passed_a_wrong_mean_and_the_uncorrected_one_fails_a_right_one(repetitions):
    """Why the band changed: the one-step band of M = 5 runs, [chi2(0.025, 10), chi2(0.975, 10)] / 5 =
    [0.65, 4.1] for d = 2, holds a mean NIS of 3.5 that the averaged band (M T d = 1000 dof) rejects;
    and without the time-correlation correction a consistent filter's ANEES fails far too often."""
    one_lo, one_hi = metrics.chi2_band(2, M)
    lo, hi, dof = metrics.averaged_band(np.full(T, 2.0), np.full(T, float(M)))
    assert dof == pytest.approx(M * T * 2)
    assert (lo, hi) == pytest.approx((chi2.ppf(0.025, 1000) / 500, chi2.ppf(0.975, 1000) / 500))
    assert one_lo < 3.5 < one_hi and not lo < 3.5 < hi
    nees, _ = repetitions["consistent"]
    plain = [metrics.averaged_band(np.full(T, 4.0), np.full(T, float(M))) for _ in range(1)][0]
    inside = np.mean([plain[0] <= v.mean() <= plain[1] for v in nees])
    assert inside < 0.9  # the NEES of one run is correlated over time: M T d overstates what it holds


def test_correlation_factor_of_white_and_of_correlated_series():
    rng = np.random.default_rng(1)
    assert metrics.correlation_factor(rng.standard_normal(5000)) == pytest.approx(1.0, abs=0.15)
    phi, e = 0.8, rng.standard_normal(20000)
    ar = np.empty_like(e)
    ar[0] = e[0]
    for k in range(1, len(e)):
        ar[k] = phi * ar[k - 1] + e[k]
    # an AR(1) series: the variance of its mean is (1 + phi) / (1 - phi) = 9 times that of white noise
    assert metrics.correlation_factor(ar) == pytest.approx(9.0, rel=0.2)
    assert metrics.correlation_factor([1.0, 2.0]) == 1.0  # too short to say: no correction
