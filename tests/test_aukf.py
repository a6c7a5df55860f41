"""AUKF (paper 001 eq. 92-110): reduction to the UKF, noise estimation, guard, bad input.

The noise-statistics tests run on linear-Gaussian models where the truth is
known: a constant measurement bias p (eq. 106), a constant process bias q
(eq. 105), R or Q wrong by a factor 4 (eq. 107, 110). Each would fail for a
sign error in the innovation (z - z^ - p^), for Theta taken with Q^ included,
or for the wrong points in Gamma.
"""
from types import SimpleNamespace

import numpy as np
import pytest

from replay.util.errors import ReplayError
from replay.filters.p001.aukf import AUKF, final_estimate, guard_spd, history
from replay.filters.sigma import UKF
from replay.model import LinearGaussian


def linear_problem(R_true, R_model, Q, steps, seed):
    A = np.array([[1.0, 1.0], [0.0, 1.0]])
    C = np.array([[1.0, 0.0], [0.0, 1.0]])
    rng = np.random.default_rng(seed)
    truth = LinearGaussian(A, C, Q, R_true)
    x = np.zeros(2)
    xs = np.empty((steps, 2))
    for k in range(steps):
        x = A @ x + np.linalg.cholesky(Q) @ rng.standard_normal(2)
        xs[k] = x
    z = xs @ C.T + rng.standard_normal((steps, 2)) @ np.linalg.cholesky(R_true).T
    return LinearGaussian(A, C, Q, R_model), z, xs


def test_estimator_off_equals_ukf():
    from replay.models.sauv import SAUV

    model = SAUV(dt=0.5, pitch=np.full(50, 0.1), roll=np.full(50, 0.02))
    rng = np.random.default_rng(1)
    x0 = np.array([0, 0, 5, 1.5, 0, 0.1, 0.01, 0, 0, 0.3])
    z = model.h(x0, 0) + 0.1 * rng.standard_normal((50, model.nz))
    z[10:15, 0] = np.nan  # a few partial rows
    z[20] = np.nan  # one predict-only row
    P0 = np.eye(10) * 0.5
    a = AUKF(adapt=False).run(model, z, x0, P0)
    u = UKF().run(model, z, x0, P0)
    assert a.diverged_at is None and u.diverged_at is None
    assert np.max(np.abs(a.x - u.x)) <= 1e-12
    assert np.max(np.abs(a.P - u.P)) <= 1e-12
    # and the estimator switched on changes the answer
    on = AUKF().run(model, z, x0, P0)
    assert np.max(np.abs(on.x[:5] - u.x[:5])) > 1e-6


def test_R_estimate_converges_with_Q_known():
    Q = np.diag([0.01, 0.01])
    R_true = np.diag([4.0, 1.0])
    model, z, _ = linear_problem(R_true, 4 * np.eye(2) * 3.0, Q, 3000, seed=3)
    est = AUKF(adapt_q=False, keep_history=True).run(model, z, np.zeros(2), np.eye(2))
    assert est.diverged_at is None
    R_hist = est.info["history"]["R"]
    assert R_hist.shape == (3000, 2, 2)
    R_mean = R_hist[-1000:].mean(axis=0)
    rel = np.abs(np.diagonal(R_mean) - np.diagonal(R_true)) / np.diagonal(R_true)
    assert rel.max() < 0.10, (np.diagonal(R_mean), rel)


def test_both_unknown_stays_finite_and_counts_guard():
    Q = np.diag([0.01, 0.01])
    model, z, xs = linear_problem(np.diag([4.0, 1.0]), np.eye(2) * 0.1, Q * 10, 3000, seed=4)
    est = AUKF().run(model, z, np.zeros(2), np.eye(2))
    assert est.diverged_at is None
    assert np.all(np.isfinite(est.x)) and np.all(np.isfinite(est.P))
    info = est.info
    assert info["adapt_updates"] == 3000
    # d_1 = 1: the first update replaces Q0 by a one-sample estimate, which is singular
    assert info["guard_q"] >= 1 and isinstance(info["guard_r"], int)
    for M in (info["Q_hat"], info["R_hat"]):
        assert np.allclose(M, M.T) and np.linalg.eigvalsh(M).min() > 0


def test_guard_clips_in_prior_units():
    prior = np.diag([100.0, 1e-4])
    s = 1.0 / np.sqrt(np.diagonal(prior))
    M, fired = guard_spd(np.diag([50.0, 2e-4]), s, 1e-3)
    assert fired == 0 and np.allclose(M, np.diag([50.0, 2e-4]))
    M, fired = guard_spd(np.diag([50.0, -1e-4]), s, 1e-3)
    assert fired == 1
    assert M[0, 0] == pytest.approx(50.0) and M[1, 1] == pytest.approx(1e-3 * 1e-4)


@pytest.mark.parametrize("b", [0.0, 1.0, -0.5, 1.5])
def test_bad_forgetting_factor(b):
    with pytest.raises(ReplayError, match="forgetting"):
        AUKF(forgetting=b)


def test_non_pd_model_noise_refused():
    model = LinearGaussian(np.eye(2), np.eye(2), np.diag([1.0, -1.0]), np.eye(2))
    with pytest.raises(ReplayError, match="model Q must be positive definite"):
        AUKF().run(model, np.zeros((3, 2)), np.zeros(2), np.eye(2))
    model = LinearGaussian(np.eye(2), np.eye(2), np.eye(2), np.array([[1.0, 2.0], [2.0, 1.0]]))
    with pytest.raises(ReplayError, match="model R must be positive definite"):
        AUKF().run(model, np.zeros((3, 2)), np.zeros(2), np.eye(2))


# stable AR(1) states measured directly: the state's mean is known to be 0, so a
# constant offset in z is identifiable as p (or, with p known, as q)
A_AR = np.diag([0.9, 0.8])
Q_AR = np.diag([0.1, 0.2])
R_AR = np.diag([1.0, 0.5])


def ar_problem(steps, seed, Q=Q_AR, R=R_AR, q=0.0, p=0.0):
    rng = np.random.default_rng(seed)
    x, xs = np.zeros(2), np.empty((steps, 2))
    LQ = np.linalg.cholesky(Q)
    for k in range(steps):
        x = A_AR @ x + LQ @ rng.standard_normal(2) + q
        xs[k] = x
    z = xs + rng.standard_normal((steps, 2)) @ np.linalg.cholesky(R).T + p
    return LinearGaussian(A_AR, np.eye(2), Q_AR, R_AR), z, xs


def rmse(est, xs, last=1000):
    return np.sqrt(np.mean((est.x[-last:] - xs[-last:]) ** 2, axis=0))


def aukf_and_ukf(model, z, **aukf_params):
    x0, P0 = np.zeros(2), np.eye(2)
    return (AUKF(keep_history=True, **aukf_params).run(model, z, x0, P0), UKF().run(model, z, x0, P0))


def nees(est, xs, last=1000):
    e = est.x[-last:] - xs[-last:]
    return float(np.mean(np.einsum("ki,kij,kj->k", e, np.linalg.inv(est.P[-last:]), e)))


def test_measurement_bias_p_converges_and_beats_ukf():
    p = np.array([3.0, -2.0])
    model, z, xs = ar_problem(3000, 1, p=p)
    a, u = aukf_and_ukf(model, z, adapt_means="p", adapt_q=False, adapt_r=False)
    p_avg = a.info["history"]["p"][-1000:].mean(axis=0)
    assert np.all(np.abs(p_avg - p) < 0.25), p_avg
    assert np.all(a.info["q_hat"] == 0.0)
    assert np.all(rmse(a, xs) < 0.4 * rmse(u, xs)), (rmse(a, xs), rmse(u, xs))


def test_process_bias_q_converges():
    q = np.array([0.5, -0.3])
    model, z, xs = ar_problem(3000, 2, q=q)
    a, u = aukf_and_ukf(model, z, adapt_means="q", adapt_q=False, adapt_r=False)
    q_avg = a.info["history"]["q"][-1000:].mean(axis=0)
    assert np.all(np.abs(q_avg - q) < 0.05), q_avg
    assert np.all(a.info["p_hat"] == 0.0)
    assert rmse(a, xs)[0] < 0.5 * rmse(u, xs)[0]


def test_q_and_p_together_only_their_combined_effect_is_identified():
    """z's mean is q / (1 - a) + p: with both estimators on (the paper), only that sum is
    pinned down; the split, and hence the state estimate, is not (why AUKF loses in 001.md)."""
    p = np.array([3.0, -2.0])
    model, z, xs = ar_problem(3000, 1, p=p)
    a = AUKF(adapt_q=False, adapt_r=False, keep_history=True).run(model, z, np.zeros(2), np.eye(2))
    h = a.info["history"]
    combined = h["q"][-1000:].mean(axis=0) / (1 - np.diagonal(A_AR)) + h["p"][-1000:].mean(axis=0)
    assert np.all(np.abs(combined - p) < 0.3), combined
    assert np.abs(h["q"][-1000:, 0].mean()) > 0.1  # part of the measurement bias went into q-hat
    assert rmse(a, xs)[0] > 1.0  # ... and into the state estimate


@pytest.mark.parametrize("unknown, tol", [("R", 0.10), ("Q", 0.15)])
def test_noise_times_4_is_estimated_and_nees_is_consistent(unknown, tol):
    """True R (or Q) is 4x the model's; the other one is known and not adapted."""
    scaled = {"R": 4 * R_AR} if unknown == "R" else {"Q": 4 * Q_AR}
    model, z, xs = ar_problem(3000, 3 if unknown == "R" else 4, **scaled)
    a, u = aukf_and_ukf(model, z, adapt_means="none", adapt_q=unknown == "Q", adapt_r=unknown == "R")
    avg = np.diagonal(a.info["history"][unknown][-1000:].mean(axis=0))
    assert np.all(np.abs(avg / np.diagonal(scaled[unknown]) - 1) < tol), avg
    assert 1.7 < nees(a, xs) < 2.3  # E[NEES] = nx = 2
    assert nees(u, xs) > 3.5  # the UKF with the nominal noise is overconfident


@pytest.mark.parametrize("guard", ["biased", "previous", "clip"])
def test_first_update_guard(guard):
    """d_1 = 1: one innovation replaces R0 by eps eps' - Gamma, indefinite for nz = 2."""
    model = LinearGaussian(np.eye(2), np.eye(2), np.eye(2) * 0.1, np.eye(2))
    est = AUKF(guard=guard, adapt_means="none").run(model, np.array([[3.0, 0.0]]), np.zeros(2), np.eye(2))
    assert est.info["guard_r"] == 1
    R = est.info["R_hat"]
    if guard == "clip":
        assert np.linalg.eigvalsh(R).min() == pytest.approx(1e-3)
    else:  # nothing PD to fall back on from one sample: the prior stays
        assert np.array_equal(R, np.eye(2))


def test_biased_guard_uses_eq_73():
    """When eps eps' - Gamma would make R-hat indefinite, R-hat <- (1 - d) R-hat + d eps eps'."""
    model = LinearGaussian(np.eye(2), np.eye(2), np.eye(2) * 0.1, np.eye(2))
    z = np.array([[0.0, 0.0], [0.0, 0.0]])
    est = AUKF(adapt_means="none", adapt_q=False, keep_history=True, forgetting=0.5).run(
        model, z, np.zeros(2), np.eye(2))
    R1, R2 = est.info["history"]["R"]
    assert np.array_equal(R1, np.eye(2))  # eps = 0: eq. 107 gives -Gamma, guard keeps R0 (d = 1)
    assert np.allclose(R2, (1 - 1 / 1.5) * R1)  # d_2 = (1 - b) / (1 - b^2) = 1 / 1.5, eps = 0
    assert est.info["guard_r"] == 2


def test_bad_guard_and_means_refused():
    with pytest.raises(ReplayError, match="guard must be one of"):
        AUKF(guard="eig")
    with pytest.raises(ReplayError, match="adapt_means must be one of both, q, p, none"):
        AUKF(adapt_means="x")
    with pytest.raises(ReplayError, match="adapt_means"):
        AUKF(adapt_means=False)  # a string: one name per choice


@pytest.mark.parametrize("means", ["both", "none"])
def test_unobservable_drift_is_not_learnt(means):
    """A drift c of an unmeasured state (the current in water track, docs/reproduction/001.md):
    no innovation carries it, so q-hat does not learn it and the AUKF (the paper's, or Q-hat and
    R-hat only) keeps the dead-reckoning error c*k like the UKF."""
    A = np.array([[1.0, 1.0], [0.0, 1.0]])
    C = np.array([[0.0, 1.0]])  # velocity measured, position not
    Q, R, c, steps = np.diag([1e-4, 1e-4]), np.array([[0.01]]), 0.05, 2000
    rng = np.random.default_rng(5)
    x, xs = np.array([0.0, 1.0]), np.empty((steps, 2))
    for k in range(steps):
        x = A @ x + np.sqrt(np.diagonal(Q)) * rng.standard_normal(2) + [c, 0.0]
        xs[k] = x
    z = xs[:, 1:] + 0.1 * rng.standard_normal((steps, 1))
    model = LinearGaussian(A, C, Q, R)
    x0, P0 = np.array([0.0, 1.0]), np.diag([1e-4, 0.01])
    a = AUKF(adapt_means=means, keep_history=True).run(model, z, x0, P0)
    u = UKF().run(model, z, x0, P0)
    drift = c * steps
    assert xs[-1, 0] - u.x[-1, 0] == pytest.approx(drift, rel=0.05)
    err = xs[-1, 0] - a.x[-1, 0]
    if means == "none":  # Q-hat, R-hat only: the UKF's dead-reckoning error
        assert err == pytest.approx(drift, rel=0.1)
    else:  # the paper's: q-hat is no estimate of c (here of the opposite sign) and adds its own drift
        assert abs(a.info["history"]["q"][-1000:, 0].mean() - c) > 0.5 * c
        assert err > 1.2 * drift


def test_final_estimate_and_history_read_the_runs_info():
    """Mean over runs of the last Q̂ (its diagonal), q̂ (a component or the mean of |components|), guard firings;
    the history as (runs, updates) per component."""
    infos = [
        {"Q_hat": np.diag([1.0, 3.0]), "q_hat": np.array([-2.0, 4.0]), "guard_q": 2, "history": {"q": np.eye(3)[:, :2]}},
        {"Q_hat": np.diag([5.0, 7.0]), "q_hat": np.array([2.0, -6.0]), "guard_q": 0, "history": {"q": np.ones((3, 2))}},
    ]
    runs = [SimpleNamespace(info=info) for info in infos]
    assert final_estimate(runs, "Q_hat") == 4.0  # mean of (2, 6)
    assert final_estimate(runs, "Q_hat", component=1) == 5.0
    assert final_estimate(runs, "q_hat", component=0) == 0.0
    assert final_estimate(runs, "q_hat", component=0, magnitude=True) == 2.0
    assert final_estimate(runs, "q_hat", magnitude=True) == 3.5  # mean of (3, 4)
    assert final_estimate(runs, "guard_q") == 1.0
    assert np.array_equal(history(runs, "q", 1), [[0.0, 1.0, 0.0], [1.0, 1.0, 1.0]])
    model, z, _ = linear_problem(np.eye(2), np.eye(2), 0.01 * np.eye(2), 50, 0)
    est = AUKF(keep_history=True).run(model, z, np.zeros(2), np.eye(2))
    assert history([est] * 2, "q", 0).shape == (2, 50)
    assert np.array_equal(history([est], "q", 0)[0, -1], est.info["q_hat"][0])
    assert final_estimate([est], "R_hat", component=1) == est.info["R_hat"][1, 1]
