"""Paper 000 pieces against known answers: GM(1,1), wavelet noise, depth model, GPF, MMPF."""
import numpy as np
import pytest

from replay import registry, scorer
from replay.util.errors import ReplayError
from replay.filters import make_filter
from replay.filters.p000.grey import GreyPredictor, gm11_fit, gm11_predict
from replay.filters.p000.wavelet_noise import WaveletNoise, detail_matrix, wavelet_sigma
from replay.models.depth import Q_FALLBACK, Q_PRINTED, DepthModel, is_positive_definite, paper_Q
from replay.tasks.depth import DepthTask


# ---------------------------------------------------------------- GM(1,1)

@pytest.mark.parametrize("c, r, floor", [(2.0, 1.07, 1.0), (5.0, 0.97, 1.0), (0.3, 1.2, None),
                                         (5.0, 0.93, None)])
def test_gm11_exact_on_exponential(c, r, floor):
    k = np.arange(1, 31)
    z = c * r**k  # (windows dipping below the shift floor of 1.0 are tested with the shift off)
    assert gm11_predict(z, floor=floor) == pytest.approx(c * r**31, abs=1e-9, rel=0)
    a, b = gm11_fit(z)
    assert a == pytest.approx(-2 * (r - 1) / (r + 1), rel=1e-9)  # the exact least-squares answer


def test_gm11_continuous_response_is_eq12_and_biased():
    k = np.arange(1, 31)
    z = 2.0 * 1.07**k
    a, b = gm11_fit(z)
    eq12 = (1 - np.exp(a)) * (z[0] - b / a) * np.exp(-a * 30)
    assert gm11_predict(z, response="continuous") == pytest.approx(eq12, rel=1e-12)
    assert abs(eq12 - 2.0 * 1.07**31) > 1e-3  # why the discrete response is the default


def test_gm11_printed_eq12_factor_is_about_the_negated_prediction():
    """Eq. 12 as printed, (1 - e^-a), is the derived response times -e^-a: the grey particles of
    GPF with grey_response=printed land near -z (why 'continuous' uses the derived factor)."""
    k = np.arange(1, 31)
    z = 2.0 * 1.07**k  # above the shift floor: no conditioning shift
    a, _ = gm11_fit(z)
    cont = gm11_predict(z, response="continuous")
    assert gm11_predict(z, response="printed") == pytest.approx(-np.exp(-a) * cont, rel=1e-12)
    assert gm11_predict(np.full(30, 3.7), response="printed") == 3.7  # a constant predicts itself
    ramp = 5.0 + 0.01 * k  # a slow trend far from 0: tiny a, so the printed response is about -z
    assert gm11_predict(ramp, response="printed") == pytest.approx(-5.31, rel=0.01)
    assert make_filter("gpf", grey_response="printed").params()["grey_response"] == "printed"
    with pytest.raises(ReplayError, match="grey_response"):
        make_filter("gpf", grey_response="eq12")


@pytest.mark.parametrize("value", [3.7, 0.0, -2.5, 1e-3])
def test_gm11_constant_exactly(value):
    assert gm11_predict(np.full(30, value)) == value
    assert gm11_predict(np.full((30, 2), value)).tolist() == [value, value]


def test_gm11_shift_conditions_ramps_through_zero():
    k = np.arange(1, 31)
    ramp = 0.1 * k - 1.0  # crosses zero: raw GM(1,1) is meaningless here
    assert gm11_predict(ramp) == pytest.approx(2.1, abs=0.1 * 0.05)  # within 1/20 of a step
    assert abs(gm11_predict(ramp, shift_ratio=10.0) - 2.1) > abs(gm11_predict(ramp) - 2.1)
    # vectorised over channels = channel by channel
    z = np.column_stack([ramp, 2.0 * 1.07**k, np.sin(k / 7)])
    np.testing.assert_allclose(GreyPredictor(30)(z), [gm11_predict(c) for c in z.T], rtol=1e-12)


def test_gm11_too_short():
    with pytest.raises(ReplayError, match="at least 3"):
        gm11_predict(np.ones(2))


# ---------------------------------------------------------------- wavelet noise

def test_db6_detail_annihilates_degree_5():
    D = detail_matrix(50, "db6")
    assert D.shape == (20, 50)
    k = np.arange(50.0)
    for p in range(6):
        assert np.abs(D @ k**p).max() < 1e-12 * np.abs(k**p).max()
    assert np.abs(D @ k**6).max() > 100.0  # six vanishing moments, not seven (342 here)
    np.testing.assert_allclose((D * D).sum(axis=1), 1.0, rtol=1e-12)  # unit energy


def test_wavelet_recovers_sigma_on_polynomial_plus_noise():
    rng = np.random.default_rng(7)
    t = np.linspace(-1, 1, 3000)
    poly = 3 + 2 * t - 5 * t**2 + 4 * t**3 + t**4 - 6 * t**5
    sigma = 0.1
    s = wavelet_sigma(poly + sigma * rng.standard_normal(len(t)), window=50)
    assert np.isnan(s[:49]).all() and np.isfinite(s[49:]).all()
    assert np.mean(s[49:]) == pytest.approx(sigma, rel=0.10)
    # the polynomial alone gives (almost) nothing
    assert np.nanmax(wavelet_sigma(poly, window=50)) < 1e-9


def test_wavelet_tracks_a_change_of_noise():
    rng = np.random.default_rng(3)
    x = np.concatenate([0.05 * rng.standard_normal(500), 0.4 * rng.standard_normal(500)])
    s = wavelet_sigma(x)
    assert np.mean(s[100:500]) == pytest.approx(0.05, rel=0.15)
    assert np.mean(s[600:]) == pytest.approx(0.4, rel=0.15)
    W = WaveletNoise()
    np.testing.assert_allclose(W.sigma(np.column_stack([x[:50], 2 * x[:50]])), [s[49], 2 * s[49]], rtol=1e-12)


def test_wavelet_bad_window():
    with pytest.raises(ReplayError, match="shorter than the db6 filter"):
        WaveletNoise(window=10)
    with pytest.raises(ReplayError, match="longer than the series"):
        wavelet_sigma(np.ones(30), window=50)


# ---------------------------------------------------------------- model

def test_printed_Q_is_not_positive_definite_so_fallback():
    assert not is_positive_definite(Q_PRINTED)
    Q, why = paper_Q()
    np.testing.assert_array_equal(Q, Q_FALLBACK)
    assert "not positive definite" in why


def test_depth_model_eq4():
    m = DepthModel(dt=0.05)
    x = np.array([[10.0, 2.0, 0.3]])
    u = np.array([[0.01, 0.5, -0.1]])
    y = m.apply(x, u, 0)
    np.testing.assert_allclose(y, [[10.0 + 2.5 * np.sin(0.2) * 0.05 + 0.01, 2.5, 0.2]])
    np.testing.assert_allclose(m.f(x, 0), m.apply(x, np.zeros_like(x), 0))
    J = m.F(x[0], 0)
    Jn = m._numeric_jacobian(m.f, x[0], 0, m.x_angles)
    np.testing.assert_allclose(J, Jn, atol=1e-7)


# ---------------------------------------------------------------- filters

@pytest.fixture(scope="module")
def problem():
    frame = registry.load_frame("sim/lake-depth", rng=11, first=600)
    return DepthTask().build(frame, np.random.default_rng(12))


def test_gpf_params_validated_in_constructor():
    with pytest.raises(ReplayError, match="n_grey"):
        make_filter("gpf", n_particles=100, n_grey=100)
    with pytest.raises(ReplayError, match="grey_window"):
        make_filter("gpf", grey_window=2)
    with pytest.raises(ReplayError, match="noise_window"):
        make_filter("gpf", noise_window=5)  # shorter than the 12 taps of db6
    with pytest.raises(ReplayError, match="'mmpf': transition must be a 3x3"):
        make_filter("mmpf", transition=[[0.5, 0.6], [0.5, 0.5]])
    with pytest.raises(ReplayError, match="'mmpf': ess_threshold must be a finite number in \\[0, 1\\]"):
        make_filter("mmpf", ess_threshold=1.5)
    with pytest.raises(ReplayError, match="modes must be a list of rows"):
        make_filter("mmpf", modes=[[0.0, 0.0, 0.0], [1.0, 2.0]])
    with pytest.raises(ReplayError, match="n_particles must be an integer >= 2"):
        make_filter("gpf", n_particles=1000.0)
    p = make_filter("mmpf", modes=[[0, 0, 0]]).params()
    assert p["modes"] == [[0.0, 0.0, 0.0]] and make_filter("mmpf", **p).params() == p


def test_gpf_runs_reproducibly_and_uses_both_parts(problem):
    f = make_filter("gpf", n_particles=300, n_grey=30)
    a = f.run(problem.model, problem.z, problem.x0, problem.P0, np.random.default_rng(1))
    b = f.run(problem.model, problem.z, problem.x0, problem.P0, np.random.default_rng(1))
    np.testing.assert_array_equal(a.x, b.x)
    assert not a.diverged
    assert a.info["grey_steps"] == len(problem.z) - 30  # grey particles once L = 30 samples exist
    assert a.info["wavelet_steps"] == len(problem.z) - 49
    m = scorer.score_run(problem, a)
    sensor = np.sqrt(np.nanmean((problem.z[:, 0] - problem.truth_position[:, 0]) ** 2))
    assert m["depth_rmse"] < 1.5 * sensor  # no worse than the raw gauge by much
    assert set(m) >= {"depth_rmse", "speed_rmse", "pitch_rmse"}


def test_gpf_wavelet_sigma_follows_sensor_noise(problem):
    f = make_filter("gpf", n_particles=200, n_grey=20)
    est = f.run(problem.model, problem.z, problem.x0, problem.P0, np.random.default_rng(2))
    # at t = 29.95 s sim/lake-depth is in its noisy regime: base sigma (0.05 m, 0.05 m/s, 0.5 deg)
    # x 3 x drift (1 + 0.5 * 29.95 / 90); the fixed R would say (0.2, 5, 0.5 rad)
    true = np.array([0.05, 0.05, np.deg2rad(0.5)]) * 3 * (1 + 0.5 * 29.95 / 90)
    ratio = np.array(est.info["last_sigma"]) / true
    assert (ratio > 0.5).all() and (ratio < 2.0).all()
    fixed = make_filter("gpf", n_particles=200, n_grey=20, wavelet=False).run(
        problem.model, problem.z, problem.x0, problem.P0, np.random.default_rng(2))
    np.testing.assert_allclose(fixed.info["last_sigma"], [0.2, 5.0, 0.5])
    assert fixed.info["wavelet_steps"] == 0


def test_gpf_requires_direct_measurement():
    from replay.model import LinearGaussian

    m = LinearGaussian(np.eye(2), np.ones((1, 2)), np.eye(2), np.eye(1))
    with pytest.raises(ReplayError, match="h\\(x\\) = x"):
        make_filter("gpf", n_particles=50, n_grey=5).run(m, np.zeros((60, 1)), np.zeros(2), np.eye(2))


def test_mmpf_mode_switching(problem):
    f = make_filter("mmpf", n_particles=300, stay=0.9)
    est = f.run(problem.model, problem.z, problem.x0, problem.P0, np.random.default_rng(3))
    mu = est.info["mean_mode_probability"]
    assert len(mu) == 3 and sum(mu) == pytest.approx(1.0)
    assert not est.diverged
    with pytest.raises(ReplayError, match="3 rates"):
        make_filter("mmpf", modes=[[0, 0]], n_particles=10).run(
            problem.model, problem.z[:5], problem.x0, problem.P0, np.random.default_rng(0))


def test_score_reports_speed_as_extra(problem):
    est = make_filter("ekf").run(problem.model, problem.z, problem.x0, problem.P0)
    m = scorer.score_run(problem, est)
    truth_v = problem.truth_extra["speed"][0]
    ok = np.isfinite(est.x[:, 1])
    assert m["speed_rmse"] == pytest.approx(np.sqrt(np.mean((est.x[ok, 1] - truth_v[ok]) ** 2)))


# ---------------------------------------------------------------- PFs against the EKF

@pytest.fixture(scope="module")
def near_linear():
    """A depth model with small, known Q and R (pitch 0.3 deg / 1 deg) and data drawn from it:
    nearly linear, so the EKF is close to optimal and a correct PF must agree with it."""
    from replay.filters.kalman import EKF

    Q = np.diag([0.01**2, 0.02**2, np.deg2rad(0.3) ** 2])
    R = np.diag([0.1**2, 0.2**2, np.deg2rad(1.0) ** 2])
    m = DepthModel(Q, R, 0.05)
    rng = np.random.default_rng(0)
    x = np.empty((600, 3))
    s = np.array([[5.0, 1.5, 0.2]])
    for k in range(len(x)):
        s = m.sample_f(s, k, rng)
        x[k] = s[0]
    z = x + rng.standard_normal(x.shape) * np.sqrt(np.diag(R))
    ekf = EKF().run(m, z, x[0], R)
    err = np.sqrt(np.mean((ekf.x - x)[50:] ** 2, axis=0))
    return m, z, x, R, ekf, err


@pytest.mark.parametrize("name, params, bound", [
    ("gpf", {"grey": False, "wavelet": False}, 0.3),  # a bootstrap PF with the fixed R
    ("mmpf", {"modes": [[0.0, 0.0, 0.0]]}, 0.3),      # one mode: the same bootstrap PF
    ("gpf", {"grey": False}, 0.6),                    # wavelet R ~ the true R: close, noisier
])
def test_particle_filters_agree_with_ekf_on_a_near_linear_model(near_linear, name, params, bound):
    """Catches a wrong motion model in the particles, process noise scaled by T (Q T instead of Q
    per step, eq. 4: ratios ~4) and the wavelet sigma used as a variance (ratios ~1.1)."""
    m, z, x, R, ekf, err = near_linear
    est = make_filter(name, **params).run(m, z, x[0], R, np.random.default_rng(1))
    gap = np.sqrt(np.mean((est.x - ekf.x)[50:] ** 2, axis=0))
    assert (gap < bound * err).all(), gap / err


def test_gpf_estimate_is_weighted_mean_before_resampling(near_linear):
    """Eq. 24 then step 5: the estimate is sum w^j x^j of the weighted particles of step k."""
    m, z, x, R, _, _ = near_linear
    f = make_filter("gpf", n_particles=200, n_grey=20)
    from replay.filters.base import State

    state = State(m, np.random.default_rng(4))
    f.start(state, x[0], R)
    for k in range(40):
        f.predict(state, k)
        f.update(state, z[k], k, None)
        xk, _ = f.estimate(state)
    w, P = state.w, state.particles
    assert xk[:2] == pytest.approx(w @ P[:, :2], abs=1e-12)
    assert xk[2] == pytest.approx(np.arctan2(w @ np.sin(P[:, 2]), w @ np.cos(P[:, 2])), abs=1e-12)
    assert np.ptp(state.w) > 0  # still weighted: resampling happens in the next predict
