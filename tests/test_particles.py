"""Particle bookkeeping (filters/particles.py): analytic values and per-run independence."""
import numpy as np
import pytest

from replay.filters import particles
from replay.filters.resampling import systematic


def test_normalise_known_log_weights():
    # log-weights log(1), log(2), log(3), log(4) + a huge offset: weights 0.1 .. 0.4 (no overflow)
    logw = np.log(np.array([[1.0, 2.0, 3.0, 4.0], [1.0, 1.0, 1.0, 1.0]])) + np.array([[1000.0], [-1000.0]])
    w, lw = particles.normalise(logw)
    np.testing.assert_allclose(w[0], [0.1, 0.2, 0.3, 0.4], rtol=1e-12)  # offset 1000: ulp 1e-13
    np.testing.assert_allclose(w[1], 0.25, rtol=1e-15)
    np.testing.assert_allclose(lw, np.log(w), rtol=1e-12)
    assert np.all(w.sum(axis=1) == pytest.approx(1.0, abs=1e-15))


def test_estimate_circular_mean_across_pi():
    # two particles at pi - 0.1 and -pi + 0.1 (component 1 an angle), equal weights:
    # mean pi (wrapped: +-pi), variance 0.01 (residuals +-0.1), not the raw mean 0
    X = np.array([[[1.0, np.pi - 0.1], [3.0, -np.pi + 0.1]]])
    w = np.array([[0.5, 0.5]])
    x, P = particles.estimate(X, w, (1,))
    assert x[0, 0] == pytest.approx(2.0)
    assert abs(abs(x[0, 1]) - np.pi) < 1e-12
    np.testing.assert_allclose(P[0], [[1.0, 0.1], [0.1, 0.01]], atol=1e-12)
    # without declaring the angle the mean is the raw (wrong) 0
    assert particles.estimate(X, w)[0][0, 1] == pytest.approx(0.0, abs=1e-12)


def test_estimate_weighted_moments():
    X = np.array([[[0.0], [1.0], [3.0]]])
    w = np.array([[0.5, 0.25, 0.25]])
    x, P = particles.estimate(X, w)
    assert x[0, 0] == pytest.approx(1.0)  # 0.25 + 0.75
    assert P[0, 0, 0] == pytest.approx(0.5 * 1 + 0.25 * 0 + 0.25 * 4)


def test_ess_uniform_and_degenerate():
    w = np.vstack([np.full(8, 1 / 8), np.eye(8)[3], np.r_[np.full(4, 0.25), np.zeros(4)]])
    np.testing.assert_allclose(particles.ess(w), [8.0, 1.0, 4.0], rtol=1e-15)


def test_resample_only_below_threshold_and_own_generator():
    N = 8
    w = np.vstack([np.full(N, 1 / N), np.eye(N)[2], np.r_[np.full(4, 0.25), np.zeros(4)]])  # ESS 8, 1, 4
    rngs = [np.random.default_rng(s) for s in (1, 2, 3)]
    before = [g.bit_generator.state for g in rngs]
    out = particles.resample(w, rngs, "systematic", threshold=0.6)  # below 4.8: runs 1 and 2
    assert sorted(out) == [1, 2]
    assert (out[1] == 2).all()  # all mass on particle 2
    assert rngs[0].bit_generator.state == before[0]  # run 0 drew nothing
    # run 2 drew exactly what systematic resampling with its own generator draws
    np.testing.assert_array_equal(out[2], systematic(w[2], np.random.default_rng(3)))
    assert set(out[2]) <= {0, 1, 2, 3} and np.bincount(out[2], minlength=4)[:4].tolist() == [2, 2, 2, 2]
    # threshold 1 resamples every run but a uniform one (ESS = N is not < N); 0 never
    assert sorted(particles.resample(w, [np.random.default_rng(0) for _ in range(3)], threshold=1.0)) == [1, 2]
    assert particles.resample(w, rngs, threshold=0.0) == {}
    # a batch's draws equal each run's own
    m = particles.resample(w, [np.random.default_rng(7) for _ in range(3)], "multinomial", 1.0)
    np.testing.assert_array_equal(m[2], particles.resample(w[2:], [np.random.default_rng(7)], "multinomial")[0])


def test_roughen_standard_deviation():
    # particles spread over [0, 2] in component 0 and [0, 10] in component 1: E = (2, 10)
    N, K = 4000, 0.2
    X = np.zeros((N, 2))
    X[0] = [2.0, 10.0]
    out = particles.roughen(X.copy(), K, np.random.default_rng(5))  # in place, returned
    expected = K * np.array([2.0, 10.0]) * N ** (-1 / 2)
    jitter = out - X
    np.testing.assert_allclose(jitter.std(axis=0), expected, rtol=0.05)  # 5 % ~ 4.5 standard errors
    # exactly: the same draw from the same generator
    e = np.random.default_rng(5).standard_normal((N, 2))
    np.testing.assert_array_equal(out, X + e * expected)
    assert np.array_equal(particles.roughen(X.copy(), 0.0, np.random.default_rng(5)), X)


def test_batch_rows_equal_single_rows():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((4, 300, 3)) * 2
    logw = rng.standard_normal((4, 300)) * 30
    w, lw = particles.normalise(logw)
    x, P = particles.estimate(X, w, (2,))
    for m in range(4):
        w1, lw1 = particles.normalise(logw[m:m + 1])
        x1, P1 = particles.estimate(X[m:m + 1], w1, (2,))
        assert np.array_equal(w1[0], w[m]) and np.array_equal(lw1[0], lw[m])
        assert np.array_equal(x1[0], x[m]) and np.array_equal(P1[0], P[m])


def test_gaussian_initial_particles():
    X0 = np.array([[1.0, -1.0], [5.0, 0.0]])
    P0 = np.stack([np.diag([4.0, 1.0]), np.array([[2.0, 0.5], [0.5, 1.0]])])
    X = particles.gaussian(X0, P0, 20000, [np.random.default_rng(1), np.random.default_rng(2)])
    for m in range(2):
        d = np.diagonal(P0[m])
        # 5 standard errors: sqrt(P_ii / n) for the mean, sqrt((P_ii P_jj + P_ij^2) / n) for the covariance
        assert np.all(np.abs(X[m].mean(axis=0) - X0[m]) < 5 * np.sqrt(d / 20000))
        assert np.all(np.abs(np.cov(X[m].T) - P0[m]) < 5 * np.sqrt((np.outer(d, d) + P0[m] ** 2) / 20000))
    one = particles.gaussian(X0[1:], P0[1:], 20000, [np.random.default_rng(2)])
    assert np.array_equal(one[0], X[1])


def test_compiled_kernels_equal_their_python_reference_bit_for_bit():
    """The kernels' un-jitted Python (tests/pure.py) is the readable reference: same bits."""
    from replay.filters import resampling
    from replay.util import kernels
    from pure import pure

    rng = np.random.default_rng(7)
    M, N, nx = 3, 257, 6
    X = rng.standard_normal((M, N, nx)) * 4.0
    logw = rng.standard_normal((M, N)) * 30.0
    xang = np.zeros(nx, bool)
    xang[4:] = True
    outs = []
    for k in (lambda f: f, pure):
        lw, w = logw.copy(), np.empty((M, N))
        k(particles.normalise_rows)(lw, w)
        x, P, e = np.empty((M, nx)), np.empty((M, nx, nx)), np.empty(M)
        k(particles.moments_rows)(X, w, xang, x, P)
        k(particles.ess_rows)(w, e)
        a = np.empty(N, np.int64)
        k(resampling.invert_sorted)(w[1], 0.37, a)
        zh = X[0, :, :3].copy()
        ll = np.empty(N)
        L = np.linalg.cholesky(np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]]))
        k(kernels.gauss_loglik)(zh, np.array([0.1, 3.0, -3.1]), np.array([False, True, True]),
                                False, L, np.ones(1), 1.7, ll)
        outs.append((lw, w, x, P, e, a, ll))
    for c, p in zip(*outs):
        assert np.array_equal(c, p)
    assert outs[0][4].min() > 1.0 and outs[0][5].max() < N  # sanity: real ESS, valid ancestors


def test_pf_run_equals_the_python_reference_bit_for_bit(monkeypatch):
    """A whole bootstrap-PF run with every bookkeeping kernel compiled equals the run with their
    Python reference (same random stream): the fast path is the same source."""
    from replay.filters import make_filter, resampling
    from replay.sim.auv_sonar import make_frame
    from replay.tasks import make_task
    from replay.util import kernels
    from pure import pure

    pb = make_task("sonar").build(make_frame(np.random.default_rng(1), steps=30), np.random.default_rng(2))
    flt = make_filter("pf", n_particles=64, roughening=0.2)

    def run():
        return flt.run(pb.model, pb.z, pb.x0, pb.P0, np.random.default_rng(5))

    fast = run()
    for mod, name in ((particles, "normalise_rows"), (particles, "moments_rows"), (particles, "ess_rows"),
                      (resampling, "invert_sorted"), (kernels, "gauss_loglik")):
        monkeypatch.setattr(mod, name, pure(getattr(mod, name)))
    ref = run()
    assert not fast.diverged and np.isfinite(fast.x).all()
    assert np.array_equal(fast.x, ref.x) and np.array_equal(fast.P, ref.P)
