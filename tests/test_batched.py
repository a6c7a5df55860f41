"""Batched Monte Carlo gives the numbers of one-by-one runs with the same seeds."""
import numpy as np
import pytest

from replay import registry
from replay.evaluate import filter_stream, rng_for
from replay.filters import make_filter
from replay.filters.batched import run_batched, supports
from replay.model import LinearGaussian
from replay.tasks import make_task

RUNS = 6


@pytest.fixture(scope="module")
def sonar_problems():
    task = make_task("sonar")
    return [task.build(registry.load_frame("sim/auv-sonar", rng=rng_for(4, r, 0), steps=60), rng_for(4, r, 1))
            for r in range(RUNS)]


def _both(name, problems, **params):
    flt = make_filter(name, **params)
    seq = [flt.run(p.model, p.z, p.x0, p.P0, rng_for(4, r, 2, filter_stream(name))) for r, p in enumerate(problems)]
    bat = run_batched(flt, problems[0].model, np.stack([p.z for p in problems]),
                      np.stack([p.x0 for p in problems]), np.stack([p.P0 for p in problems]),
                      [rng_for(4, r, 2, filter_stream(name)) for r in range(len(problems))])
    return seq, bat


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf"])
def test_batched_kalman_family_equals_one_by_one(sonar_problems, name):
    # Stacked LAPACK/BLAS instead of direct dpotrf/dposv/gemv: rounding-level differences only.
    seq, bat = _both(name, sonar_problems)
    for a, b in zip(seq, bat):
        assert a.diverged_at == b.diverged_at
        np.testing.assert_allclose(b.x, a.x, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(b.P, a.P, rtol=1e-10, atol=1e-12)
        assert np.isfinite(b.info["nis"]).all() and (b.info["nis_dof"] == 3).all()


def test_batched_pf_is_bit_identical(sonar_problems):
    seq, bat = _both("pf", sonar_problems[:3], n_particles=200, ess_threshold=0.5)
    for a, b in zip(seq, bat):
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert a.info["resampled"] == b.info["resampled"] > 0


def test_missing_measurements_and_divergence_per_run():
    """Runs with different NaN patterns group correctly; a run whose covariance breaks leaves the stack."""
    A, C = np.eye(2), np.array([[1.0, 0.0], [0.0, 1.0]])
    model = LinearGaussian(A, C, 0.1 * np.eye(2), 0.5 * np.eye(2))
    rng = np.random.default_rng(0)
    Z = rng.standard_normal((3, 20, 2))
    Z[0, 5] = np.nan
    Z[1, 7, 1] = np.nan
    X0 = np.zeros((3, 2))
    P0 = np.stack([np.eye(2), np.eye(2), np.eye(2)])
    P0[2] = [[1.0, 2.0], [2.0, 1.0]]  # not positive definite: the UKF's Cholesky fails at step 0
    flt = make_filter("ukf")
    bat = run_batched(flt, model, Z, X0, P0, [None] * 3)
    for m in range(2):
        one = flt.run(model, Z[m], X0[m], P0[m])
        np.testing.assert_allclose(bat[m].x, one.x, rtol=1e-12, atol=1e-12)
    assert bat[1].info["nis_dof"][7] == 1 and np.isnan(bat[0].info["nis"][5])
    assert bat[2].diverged_at == 0 and np.isnan(bat[2].x).all()


def test_supports_only_exact_builtin_classes():
    assert all(supports(make_filter(n)) for n in ("kf", "ekf", "ukf", "ckf", "pf"))

    class Custom(type(make_filter("ukf"))):
        pass

    assert not supports(Custom())
