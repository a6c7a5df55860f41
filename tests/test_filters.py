"""Filters against analytic answers: the Kalman filter on a linear-Gaussian model."""
import numpy as np
import pytest

from replay.filters import make_filter
from replay.model import LinearGaussian, Model


def plain_kalman(A, C, Q, R, z, x0, P0):
    """Textbook Kalman filter (standard covariance update), independent of replay's code."""
    x, P = x0.copy(), P0.copy()
    xs, Ps = [], []
    for zk in z:
        x = A @ x
        P = A @ P @ A.T + Q
        S = C @ P @ C.T + R
        K = P @ C.T @ np.linalg.inv(S)
        x = x + K @ (zk - C @ x)
        P = P - K @ S @ K.T
        xs.append(x)
        Ps.append(P)
    return np.array(xs), np.array(Ps)


@pytest.fixture(scope="module")
def linear_case():
    rng = np.random.default_rng(42)
    dt = 0.5
    A = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1.0]])
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0.3, 0, -0.2, 0.1]])
    Q = 0.05 * np.kron(np.eye(2), [[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]) + 1e-4 * np.eye(4)
    R = np.diag([0.5, 0.8, 0.3])
    model = LinearGaussian(A, C, Q, R)
    x = np.array([1.0, 0.5, -2.0, 0.2])
    zs = []
    for _ in range(80):
        x = A @ x + rng.multivariate_normal(np.zeros(4), Q)
        zs.append(C @ x + rng.multivariate_normal(np.zeros(3), R))
    x0, P0 = np.array([0.8, 0.4, -1.5, 0.0]), np.diag([1.0, 0.5, 1.0, 0.5])
    xs, Ps = plain_kalman(A, C, Q, R, np.array(zs), x0, P0)
    return model, np.array(zs), x0, P0, xs, Ps


@pytest.mark.parametrize("name", ["kf", "ekf", "ukf", "ckf"])
def test_kalman_variants_equal_kalman_filter(linear_case, name):
    model, z, x0, P0, xs, Ps = linear_case
    est = make_filter(name).run(model, z, x0, P0)
    assert not est.diverged
    np.testing.assert_allclose(est.x, xs, rtol=0, atol=1e-9)
    np.testing.assert_allclose(est.P, Ps, rtol=0, atol=1e-9)


@pytest.mark.parametrize("alpha", [1e-3, 0.5, 1.0])
def test_ukf_exact_for_any_alpha(linear_case, alpha):
    model, z, x0, P0, xs, Ps = linear_case
    est = make_filter("ukf", alpha=alpha).run(model, z, x0, P0)
    tol = 1e-9 if alpha >= 0.5 else 1e-6  # alpha = 1e-3 cancels weights of order 1e6
    np.testing.assert_allclose(est.x, xs, atol=tol)


def test_particle_filter_mean_matches_kalman(linear_case):
    model, z, x0, P0, xs, Ps = linear_case
    est = make_filter("pf", n_particles=20000).run(model, z, x0, P0, np.random.default_rng(7))
    sd = np.sqrt(np.diagonal(Ps, axis1=1, axis2=2))
    # Monte Carlo error of a PF mean is a small fraction of the posterior sd with 2e4 particles.
    normalised = np.abs(est.x - xs) / sd
    assert np.mean(normalised) < 0.05
    assert np.max(normalised) < 1.0  # worst step of 320 components: impoverished velocity particles
    np.testing.assert_allclose(np.sqrt(np.diagonal(est.P, axis1=1, axis2=2)).mean(0), sd.mean(0), rtol=0.05)


def test_particle_filter_is_reproducible_from_seed(linear_case):
    model, z, x0, P0, *_ = linear_case
    pf = make_filter("pf", n_particles=500)
    a = pf.run(model, z, x0, P0, np.random.default_rng(3)).x
    b = pf.run(model, z, x0, P0, np.random.default_rng(3)).x
    c = pf.run(model, z, x0, P0, np.random.default_rng(4)).x
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf", "pf"])
def test_missing_components_equal_reduced_model(linear_case, name):
    """A NaN component means: update with the others only."""
    model, z, x0, P0, *_ = linear_case
    zmiss = z.copy()
    zmiss[::3, 1] = np.nan
    zmiss[5] = np.nan  # a whole row missing: predict only
    est = make_filter(name, **({"n_particles": 300} if name == "pf" else {})).run(
        model, zmiss, x0, P0, np.random.default_rng(1))
    # Reference: the plain KF with row-dependent C, R
    A, C, Q, R = model.A, model.C, model.Q, model.R
    x, P = x0.copy(), P0.copy()
    for k, zk in enumerate(zmiss):
        x, P = A @ x, A @ P @ A.T + Q
        m = np.isfinite(zk)
        if m.any():
            Cm, Rm = C[m], R[np.ix_(m, m)]
            S = Cm @ P @ Cm.T + Rm
            K = P @ Cm.T @ np.linalg.inv(S)
            x, P = x + K @ (zk[m] - Cm @ x), P - K @ S @ K.T
    tol = 1e-9 if name != "pf" else 0.5
    np.testing.assert_allclose(est.x[-1], x, atol=tol)


class Heading(Model):
    """A heading turning at a constant rate, measured directly: crosses +-pi many times."""

    nx = nz = 2
    x_angles = (0,)
    z_angles = (0,)

    def __init__(self):
        self.Q = np.diag([1e-4, 1e-6])
        self.R = np.diag([0.05**2, 0.02**2])

    def f(self, x, k):
        y = x.copy()
        y[..., 0] += 0.1 * x[..., 1]
        return y

    def h(self, x, k):
        return np.stack([x[..., 0], x[..., 1] + 0.0 * x[..., 0]], axis=-1)


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf", "pf"])
def test_heading_across_pi(name):
    rng = np.random.default_rng(5)
    model = Heading()
    n = 300
    rate = 0.8  # rad/s: wraps about 4 times
    truth = (3.0 + rate * 0.1 * np.arange(1, n + 1) + np.pi) % (2 * np.pi) - np.pi
    z = np.column_stack([truth + rng.normal(0, 0.05, n), rate + rng.normal(0, 0.02, n)])
    z[:, 0] = (z[:, 0] + np.pi) % (2 * np.pi) - np.pi
    params = {"n_particles": 2000} if name == "pf" else {}
    est = make_filter(name, **params).run(model, z, np.array([3.0, rate]), np.diag([0.01, 0.01]),
                                          np.random.default_rng(0))
    err = (est.x[:, 0] - truth + np.pi) % (2 * np.pi) - np.pi
    assert np.all(est.x[:, 0] >= -np.pi) and np.all(est.x[:, 0] < np.pi)
    assert np.sqrt(np.mean(err**2)) < 0.04
    assert np.max(np.abs(err)) < 0.2


def test_divergence_is_reported_not_raised():
    class Exploding(LinearGaussian):
        pass

    model = Exploding(np.eye(2) * 1e200, np.eye(2), np.eye(2), np.eye(2))
    z = np.ones((20, 2))
    est = make_filter("ekf").run(model, z, np.ones(2), np.eye(2))
    assert est.diverged and est.diverged_at < 20
    assert np.isnan(est.x[est.diverged_at:]).all()


def test_wrap_values_and_shapes():
    from replay.util.angles import residual, weighted_mean, wrap

    assert wrap(np.pi) == -np.pi and wrap(-np.pi) == -np.pi
    assert wrap(3 * np.pi / 2) == pytest.approx(-np.pi / 2)
    assert np.ndim(wrap(7.0)) == 0 and wrap(7.0) == pytest.approx(7.0 - 2 * np.pi)
    a = np.linspace(-20, 20, 401).reshape(-1, 1)
    w = wrap(a)
    assert np.all((w >= -np.pi) & (w < np.pi))
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    # A residual across +-pi is small, and a mean of points straddling +-pi is near pi.
    assert residual(np.array([np.pi - 0.1]), np.array([-np.pi + 0.1]), (0,))[0] == pytest.approx(-0.2)
    pts = np.array([[np.pi - 0.1], [-np.pi + 0.1]])
    assert abs(abs(weighted_mean(pts, np.array([0.5, 0.5]), (0,))[0]) - np.pi) < 1e-12


def test_roughening_option_and_parameter_checks(linear_case):
    from replay.util.errors import ReplayError

    model, z, x0, P0, xs, Ps = linear_case
    rough = make_filter("pf", n_particles=2000, roughening=0.2)
    a = rough.run(model, z, x0, P0, np.random.default_rng(1)).x
    b = rough.run(model, z, x0, P0, np.random.default_rng(1)).x
    plain = make_filter("pf", n_particles=2000).run(model, z, x0, P0, np.random.default_rng(1)).x
    assert np.array_equal(a, b) and not np.array_equal(a, plain)
    # Jitter widens the cloud but the mean still tracks the Kalman filter.
    assert np.mean(np.abs(a - xs) / np.sqrt(np.diagonal(Ps, axis1=1, axis2=2))) < 0.3
    for bad in ({"n_particles": 0}, {"ess_threshold": 1.5}, {"roughening": -1}, {"resampling": "nope"},
                {"n_particles": 1.5}, {"n_particles": True}, {"roughening": float("nan")}, {"nope": 1}):
        with pytest.raises(ReplayError, match=f"^filter 'pf': .*{next(iter(bad))}"):
            make_filter("pf", **bad)


def test_declared_parameters_of_the_kalman_family_and_pf():
    from replay.util.errors import ReplayError

    assert make_filter("ukf").params() == {"alpha": 0.5, "beta": 2.0, "kappa": 0.0}
    assert make_filter("ckf").params() == {} and make_filter("ekf").params() == {}
    assert make_filter("pf").params() == {"n_particles": 1000, "resampling": "systematic", "ess_threshold": 1.0,
                                          "roughening": 0.0, "proposal": "auto"}
    assert make_filter("wf-pf").params() == {"n_particles": 1000, "alpha": 0.75, "weight_floor": 1e-99,
                                             "resampling": "systematic", "ess_threshold": 1.0}
    for name, bad in (("ukf", {"alpha": 0.0}), ("ukf", {"beta": -1.0}), ("ukf", {"alpha": True}),
                      ("wf-pf", {"roughening": 0.2}), ("wf-pf", {"weight_floor": 0.0}), ("kf", {"q": 1.0})):
        with pytest.raises(ReplayError, match=f"^filter '{name}': .*{next(iter(bad))}"):
            make_filter(name, **bad)
    # kappa is checked against the state dimension when the model is known: raised, not a divergence
    model = LinearGaussian(np.eye(2), np.eye(2), np.eye(2), np.eye(2))
    with pytest.raises(ReplayError, match="kappa must be > -2"):
        make_filter("ukf", kappa=-2.0).run(model, np.zeros((3, 2)), np.zeros(2), np.eye(2))


def test_filter_written_per_run_goes_through_the_default_engine():
    """A State-based filter with its own constructor: params() reports its attributes, the default
    engine loops over the runs, and an exception in one run marks that run only."""
    from replay.filters.base import Filter

    class Shrinking(Filter):
        name = "shrinking"

        def __init__(self, gain=0.5):
            self.gain = gain

        def predict(self, state, k):
            if state.x[0] > 50:
                raise ValueError("too far")

        def update(self, state, z, k, mask):
            state.x = state.x + self.gain * (np.where(np.isfinite(z), z, state.x) - state.x)
            state.P = state.P * (1 - self.gain)

    flt = Shrinking()
    assert flt.params() == {"gain": 0.5}
    model = LinearGaussian(np.eye(2), np.eye(2), np.eye(2), np.eye(2))
    Z = np.ones((3, 10, 2))
    Z[1, 4:, 0] = 200.0
    Z[2, 2, 1] = np.nan
    est = flt.run_batch(model, Z, np.zeros((3, 2)), np.stack([np.eye(2)] * 3), [None] * 3)
    assert est[0].x[2].tolist() == [0.875, 0.875] and not est[0].diverged
    assert est[2].x[2].tolist() == [0.875, 0.75]  # the missing component kept its prediction
    assert est[1].diverged_at == 5 and est[1].info["error"] == "ValueError: too far"
    assert np.isnan(est[1].x[5:]).all() and est[1].x[4, 0] == 0.9375 + 0.5 * (200.0 - 0.9375)
