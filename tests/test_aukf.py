"""AUKF (paper 001 eq. 92-110): reduction to the UKF, noise estimation, guard, bad input."""
import numpy as np
import pytest

from replay.errors import ReplayError
from replay.filters.aukf import AUKF, guard_spd
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
