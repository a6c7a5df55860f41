"""Weight-factor PF (003 eq. 27) and glint noise (003 eq. 7-10)."""
import numpy as np
import pytest

from replay.util.errors import ReplayError
from replay.filters.p003.wfpf import WeightFactorPF, temper
from replay.models.noise import Glint


def test_alpha_one_leaves_weights_unchanged():
    w = np.random.default_rng(0).dirichlet(np.ones(50))
    out, logout = temper(np.log(w), 1.0)
    assert np.allclose(out, w, rtol=1e-12, atol=0)
    assert np.allclose(np.exp(logout), w, rtol=1e-12)


def test_alpha_to_zero_tends_to_uniform():
    w = np.random.default_rng(1).dirichlet(np.ones(50) * 0.2)
    spreads = [np.ptp(temper(np.log(w), a)[0]) for a in (0.5, 0.1, 1e-3, 1e-6)]
    assert all(s2 < s1 for s1, s2 in zip(spreads, spreads[1:]))
    assert np.allclose(temper(np.log(w), 1e-9)[0], 1 / 50, atol=1e-8)


def test_alpha_lifts_small_weights_lowers_large():
    w = np.array([0.01, 0.09, 0.2, 0.7])
    new = temper(np.log(w), 0.75)[0]
    assert new[0] > w[0] and new[-1] < w[-1] and new.sum() == pytest.approx(1.0)


@pytest.mark.parametrize("alpha", [0.0, -0.1, 1.01])
def test_bad_alpha(alpha):
    with pytest.raises(ReplayError, match="alpha"):
        WeightFactorPF(alpha=alpha)


@pytest.mark.parametrize("eps", [-0.01, 1.5])
def test_bad_glint_probability(eps):
    with pytest.raises(ReplayError, match="eps"):
        Glint(np.eye(2), np.eye(2), eps=eps)


def test_non_pd_glint_covariance():
    with pytest.raises(ReplayError, match="glint P2"):
        Glint(np.eye(2), np.diag([1.0, 0.0]))


def test_glint_moments_match_mixture():
    mu1, mu2 = np.array([1.0, -2.0]), np.array([-3.0, 0.5])
    P1 = np.array([[1.0, 0.3], [0.3, 0.5]])
    P2 = np.array([[9.0, -1.0], [-1.0, 4.0]])
    g = Glint(P1, P2, eps=0.3, mu1=mu1, mu2=mu2)
    mu = 0.7 * mu1 + 0.3 * mu2  # eq. 9
    assert np.allclose(g.mean, mu)
    cov = 0.7 * (P1 + np.outer(mu1, mu1)) + 0.3 * (P2 + np.outer(mu2, mu2)) - np.outer(mu, mu)
    assert np.allclose(g.cov, cov)
    n = 400_000
    e = g.sample(np.random.default_rng(2), n)
    # Monte Carlo tolerance: 5 standard errors
    se_mean = np.sqrt(np.diagonal(cov) / n)
    assert np.all(np.abs(e.mean(axis=0) - mu) < 5 * se_mean)
    S = np.cov(e.T)
    assert np.allclose(S, cov, rtol=0.02, atol=0.02)
    # the printed eq. 10 (without P1, P2) would be far off
    printed = 0.7 * np.outer(mu1, mu1) + 0.3 * np.outer(mu2, mu2) - np.outer(mu, mu)
    assert not np.allclose(S, printed, rtol=0.2)


def test_glint_logpdf_integrates_to_one_1d():
    g = Glint([[1.0]], [[16.0]], eps=0.75)
    x = np.linspace(-40, 40, 20001)[:, None]
    p = np.exp(g.logpdf(x))
    assert np.trapezoid(p, x[:, 0]) == pytest.approx(1.0, abs=1e-6)
    assert g.cov[0, 0] == pytest.approx(0.25 * 1 + 0.75 * 16)


def test_formation_end_to_end_and_diagonal_fast_path():
    from replay import evaluate  # the API: keywords in, one EvalOptions record built

    g = Glint(np.diag([25.0, 1e-4]), np.diag([25.0, 4e-4]), eps=0.75)
    e = np.random.default_rng(0).standard_normal((7, 2)) * [5, 0.01]
    full = Glint(np.array([[25.0, 1e-9], [1e-9, 1e-4]]), np.array([[25.0, 1e-9], [1e-9, 4e-4]]), eps=0.75)
    assert np.allclose(g.logpdf(e), full.logpdf(e), atol=1e-6)
    ev = evaluate("sim/uav-formation", filters=("pf", "wf-pf"), runs=2, seed=1,
                  filter_params={"pf": {"n_particles": 300}, "wf-pf": {"n_particles": 300}})
    for r in ev.results:
        assert r.summary["diverged"] == 0 and 0.5 < r.summary["pos_rmse"] < 30
        assert "vx_rmse" in r.summary


def test_tempering_is_a_widened_gaussian_likelihood():
    """With resampling at every step the prior weights are uniform, so eq. 27 gives w ∝ p(z|x)^α:
    on a Gaussian model the WF-PF is the PF whose R is R/α (docs/reproduction/003.md)."""
    from replay.filters.pf import ParticleFilter
    from replay.model import LinearGaussian

    A = np.array([[1.0, 1.0], [0.0, 1.0]])
    C = np.eye(2)
    Q, R, alpha = np.diag([0.05, 0.02]), np.diag([1.0, 0.5]), 0.4
    rng = np.random.default_rng(3)
    x, z = np.zeros(2), []
    for _ in range(30):
        x = A @ x + rng.standard_normal(2) * np.sqrt(np.diagonal(Q))
        z.append(C @ x + rng.standard_normal(2) * np.sqrt(np.diagonal(R)))
    z = np.array(z)
    tempered = WeightFactorPF(n_particles=200, alpha=alpha, weight_floor=1e-300)
    wide = ParticleFilter(n_particles=200)
    a = tempered.run(LinearGaussian(A, C, Q, R), z, np.zeros(2), np.eye(2), rng=np.random.default_rng(9))
    b = wide.run(LinearGaussian(A, C, Q, R / alpha), z, np.zeros(2), np.eye(2), rng=np.random.default_rng(9))
    assert np.max(np.abs(a.x - b.x)) < 1e-9
    # and it is not the PF with the exact likelihood
    c = wide.run(LinearGaussian(A, C, Q, R), z, np.zeros(2), np.eye(2), rng=np.random.default_rng(9))
    assert np.max(np.abs(a.x - c.x)) > 1e-3


@pytest.mark.parametrize("ratio, eps", [(2, 0.75), (10, 0.1)])
def test_bearing_glint_excess_kurtosis(ratio, eps):
    """The excess kurtosis the 003 document quotes (0.48 at the printed glint) is the sampled one."""
    g = Glint([[1.0]], [[float(ratio) ** 2]], eps=eps)
    e = g.sample(np.random.default_rng(4), 2_000_000)[:, 0]
    sample = np.mean(e**4) / np.mean(e**2) ** 2 - 3
    assert sample == pytest.approx(g.excess_kurtosis()[0], rel=0.05)
    if (ratio, eps) == (2, 0.75):
        assert g.excess_kurtosis()[0] == pytest.approx(0.48, abs=0.01)


def test_distinct_particles_counted_after_resampling():
    """The engine records per step the distinct particles after resampling (the ancestors kept):
    within [1, N], equal to the distinct ancestors of the systematic draw, and α < 1 keeps more."""
    from replay import evaluate  # the API: keywords in, one EvalOptions record built
    from replay.filters.p003.wfpf import distinct, mean_distinct

    X = np.arange(12.0).reshape(6, 2)
    assert distinct(X[[0, 0, 3, 3, 3, 5]]) == 3 and distinct(X) == 6
    kept = {}
    for a in (1.0, 0.5):
        ev = evaluate("sim/uav-formation", filters=("wf-pf",), runs=3, seed=0,
                      filter_params={"wf-pf": {"n_particles": 100, "alpha": a}})
        d = np.array([e.info["distinct"] for e in ev.results[0].estimates])
        assert d.shape == (3, len(ev.t)) and d.min() >= 1 and d.max() <= 100
        kept[a] = d.mean()
        assert np.array_equal(mean_distinct(ev.results[0].estimates), d.mean(axis=1))
    assert kept[0.5] > kept[1.0] + 5  # flatter weights: fewer copies of the heavy particles


def test_counting_changes_no_estimate():
    """The counting engine gives the estimates of the plain PF engine, bit for bit."""
    from replay.filters.p003.wfpf import mean_distinct
    from replay.filters.pf import PFEngine
    from replay.run.pipeline import build_problem
    from replay import evaluate  # the API: keywords in, one EvalOptions record built

    ev = evaluate("sim/uav-formation", filters=("wf-pf",), runs=1, seed=3)
    pb = build_problem(ev.results[0].config, 0)
    f = WeightFactorPF(n_particles=200, alpha=0.6)
    a = f.run(pb.model, pb.z, pb.x0, pb.P0, rng=np.random.default_rng(7))
    f.engine = lambda model, rngs: PFEngine(f, model, rngs)
    b = f.run(pb.model, pb.z, pb.x0, pb.P0, rng=np.random.default_rng(7))
    assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P) and "distinct" not in b.info
    assert np.isnan(mean_distinct([b])).all()  # a run without the record


def test_glint_excess_kurtosis():
    """Per axis: 3((1 − ε) + ε r⁴) / ((1 − ε) + ε r²)² − 3 for zero means; a Gaussian has none; two narrow
    components at ±1 with equal weight (a two-point law) have −2."""
    g = Glint(np.diag([1.0, 1.0]), np.diag([1.0, 4.0]), eps=0.75)
    assert g.excess_kurtosis() == pytest.approx([0.0, 3 * 12.25 / 3.25**2 - 3])  # 0.4793: the printed 0.48
    assert Glint([[1.0]], [[100.0]], eps=0.1).excess_kurtosis()[0] == pytest.approx(3 * 1000.9 / 10.9**2 - 3)
    assert Glint([[2.0]], [[9.0]], eps=0.0).excess_kurtosis()[0] == pytest.approx(0.0)
    two_point = Glint([[1e-12]], [[1e-12]], eps=0.5, mu1=[-1.0], mu2=[1.0])
    assert two_point.excess_kurtosis()[0] == pytest.approx(-2.0)
    shifted = Glint([[1.0]], [[4.0]], eps=0.75, mu2=[0.5])  # nonzero means: the central moments
    e = shifted.sample(np.random.default_rng(0), 400_000)[:, 0]
    sample = np.mean((e - e.mean()) ** 4) / np.var(e) ** 2 - 3
    assert sample == pytest.approx(shifted.excess_kurtosis()[0], abs=0.03)
