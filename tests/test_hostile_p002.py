"""Paper 002, issue 27: the classic strong-tracking form of the STCKF (lambda F P F' + Q) and its refusals."""
from __future__ import annotations

import numpy as np
import pytest

from replay.filters.p002.stckf import STCKF
from replay.model import LinearGaussian
from replay.util.errors import ReplayError


def linear_mismatch():
    rng = np.random.default_rng(0)
    A, C = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    model = LinearGaussian(A, C, 0.01 * np.eye(2), [[1.0]])
    x, z = np.zeros(2), []
    for _ in range(60):
        x = A @ x + rng.standard_normal(2) * 0.1
        z.append(C @ x + rng.standard_normal(1))
    z = np.array(z)
    z[40:] += 50.0  # a 50-sigma jump: lambda > 1
    return A, C, model, z


def test_classic_form_is_the_kalman_filter_with_prior_lambda_FPF_plus_Q():
    A, C, model, z = linear_mismatch()
    Q, R = 0.01 * np.eye(2), np.eye(1)
    run = STCKF(form="classic").run(model, z, np.zeros(2), np.eye(2))
    lam = run.info["lambda"]
    assert (lam > 1).sum() >= 1
    for k in range(1, len(z)):  # one step from the filter's own posterior (predict, then update: filters/base.py)
        # (step by step: the fading factor amplifies rounding, ~10x per step after lambda = 2e3)
        x, P = A @ run.x[k - 1], lam[k] * (A @ run.P[k - 1] @ A.T) + Q
        S = C @ P @ C.T + R
        K = P @ C.T @ np.linalg.inv(S)
        x, P = x + K @ (z[k] - C @ x), P - K @ S @ K.T
        assert np.allclose(run.x[k], x, rtol=1e-9, atol=1e-12), k
        assert np.allclose(run.P[k], P, rtol=1e-9, atol=1e-12 * np.abs(P).max()), k
    innovation = STCKF().run(model, z, np.zeros(2), np.eye(2))
    assert not np.allclose(innovation.x, run.x)  # the two forms differ where lambda > 1


def test_classic_form_without_scaled_prior_is_refused():
    with pytest.raises(ReplayError, match="scale_prior=false applies to form=innovation only"):
        STCKF(form="classic", scale_prior=False)
    with pytest.raises(ReplayError, match="form"):
        STCKF(form="Classic")
