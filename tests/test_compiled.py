"""The compiled kernels (replay.filters.p002.compiled, compiled_util), the library's only paper-002 engine,
against the numpy test oracle (tests/oracle_p002.py)."""
from __future__ import annotations

import numpy as np
import pytest

from replay.data import registry
from replay.util.seeds import rng_for
from replay.filters import make_filter
from replay.filters.compiled import Kernel, copies
from replay.filters.p002 import compiled_util, gwo, stcpf
from replay.models.auv_sonar import AUVSonar
from replay.models.random_walk import RandomWalkPosition
from replay.models.ungm import UNGM
from replay.tasks import make_task

from oracle_p002 import batched_cholesky, gwo_optimize, oracle_filter
from replay.models.depth import DepthModel
from replay.util.errors import ReplayError
import numba


@pytest.fixture(scope="module")
def sonar():
    return make_task("sonar").build(registry.load_frame("sim/auv-sonar", rng=rng_for(0, 0, 0)), rng_for(0, 0, 1))


MODELS = {
    "auv-sonar": lambda: AUVSonar(dt=0.7, yaw_rate=0.3, origin=(5.0, -3.0, 1.0)),
    "ungm": lambda: UNGM(Q=2.0, R=3.0),
    "random-walk": lambda: RandomWalkPosition(np.eye(3), 2 * np.eye(3)),
}


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.slow
def test_model_kernels_equal_the_model_on_stacks(name):
    """The kernels as the compiled filters call them (one state, ``kernel_params``) give what the
    model's array methods (derived from them: tests/test_models.py checks those against numpy)
    give on a stack of states (to rounding: numba may vectorise the stack's loop differently)."""
    m = MODELS[name]()
    f, h, F, H = m.kernels()
    k = 3
    pf, ph = m.kernel_params(k)
    X = np.random.default_rng(0).normal([40, -20, -30, 8, 0.5, 2.5][:m.nx], [30, 30, 30, 2, 0.5, 2.0][:m.nx],
                                        (50, m.nx))
    fX, hX, FX, HX = m.f(X, k), m.h(X, k), m.F(X, k), m.H(X, k)
    for i, x in enumerate(X):
        out, J, z, Jh = np.empty(m.nx), np.empty((m.nx, m.nx)), np.empty(m.nz), np.empty((m.nz, m.nx))
        f(x, pf, out)
        np.testing.assert_allclose(out, fX[i], rtol=1e-14, atol=1e-13)
        F(x, pf, J)
        np.testing.assert_allclose(J, FX[i], rtol=1e-14, atol=1e-13)
        h(x, ph, z)
        np.testing.assert_allclose(z, hX[i], rtol=1e-14, atol=1e-13)
        H(x, ph, Jh)
        np.testing.assert_allclose(Jh, HX[i], rtol=1e-14, atol=1e-13)


def test_sonar_jacobian_kernel_is_zero_at_the_sonar():
    m = MODELS["auv-sonar"]()
    Jh = np.full((3, 6), 7.0)
    m.kernels()[3](np.array([5.0, -3.0, 1.0, 1, 0, 0]), m.kernel_params(0)[1], Jh)
    assert not Jh.any()


@pytest.mark.parametrize("params", [{}, {"proposal": "ckf"}, {"m_form": "printed"}, {"scale_prior": False},
                                    {"prior_cov": "transition"}, {"prior_cov": "transition", "m_form": "printed"}])
@pytest.mark.slow
def test_compiled_cubature_particle_filter_equals_numpy(sonar, params):
    """STCPF / CPF: the compiled step and the numpy engine agree to rounding over 100 steps.
    The printed M = H Phi H' gives fading factors of 1e3 and more that amplify rounding
    (and both blow up near step 56), and the unscaled prior makes covariances indefinite
    (repaired): 10 steps, to 1e-6 relative."""
    printed = params.get("m_form") == "printed" or params.get("scale_prior") is False
    z = sonar.z[:10] if printed else sonar.z
    a = make_filter("stcpf", **params).run(sonar.model, z, sonar.x0, sonar.P0, np.random.default_rng(5))
    b = oracle_filter("stcpf", **params).run(sonar.model, z, sonar.x0, sonar.P0, np.random.default_rng(5))
    assert a.diverged is False and b.diverged is False
    np.testing.assert_allclose(a.x, b.x, rtol=1e-6 if printed else 0, atol=1e-9)
    np.testing.assert_allclose(a.P, b.P, rtol=1e-5 if printed else 1e-7, atol=1e-6 if printed else 1e-9)
    if "lambda_mean" in b.info:
        assert a.info["lambda_mean"] == pytest.approx(b.info["lambda_mean"], rel=1e-5 if printed else 1e-10)
        if params.get("prior_cov") == "transition" and not printed:  # propagated M = 0: lambda = 1
            assert a.info["lambda_mean"] == 1.0
        else:
            assert b.info["lambda_mean"] > 1.0  # the fading factor acts: the STCKF branch is exercised
    np.testing.assert_allclose(a.info["ess"], b.info["ess"], rtol=1e-6 if printed else 1e-7)


ABLATIONS = [("igwo-stcpf", {"move_components": "observed"}), ("igwo-stcpf", {"fitness": "posterior"}),
             ("igwo-stcpf", {"a_form": "printed"}), ("igwo-stcpf", {"prior_cov": "transition"}),
             ("gwo-pf", {"fitness": "posterior", "move_components": "observed"}),
             ("pso-cpf", {"fitness": "posterior", "move_components": "observed"})]


@pytest.mark.parametrize("name,params", [("igwo-stcpf", {}), ("igwo-pf", {}), ("gwo-pf", {})] + ABLATIONS)
@pytest.mark.slow
def test_compiled_swarm_equals_numpy_until_rounding_flips_a_leader(sonar, name, params):
    """The swarm collapses onto near-ties, so rounding eventually picks another leader and the
    runs part; before that (the first 10 steps) they agree to 1e-8. Also the ablations'
    parameters (moved components, posterior-type fitness, printed a(t), transition prior)."""
    a = make_filter(name, **params).run(sonar.model, sonar.z[:10], sonar.x0, sonar.P0, np.random.default_rng(5))
    b = oracle_filter(name, **params).run(sonar.model, sonar.z[:10], sonar.x0, sonar.P0, np.random.default_rng(5))
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-8)
    assert a.info["mean_fitness_gain"] == pytest.approx(b.info["mean_fitness_gain"], rel=1e-6)
    assert a.info["mean_fitness_gain"] > 0


def gappy(z):
    """The sonar measurements with whole steps missing (predict-only) and single components missing."""
    z = z.copy()
    z[[3, 4, 11]] = np.nan  # no measurement: draw from the prediction
    z[[6, 7, 8, 15], 1] = np.nan  # bearing missing (one set of measured components)
    z[[9, 16], 0] = np.nan  # range missing (another set: the STCKF's V restarts)
    z[17, 1:] = np.nan
    return z


@pytest.mark.parametrize("params", [{}, {"proposal": "ckf"}])
@pytest.mark.slow
def test_compiled_predict_only_and_masked_steps_equal_the_oracle(sonar, params):
    """Steps without a measurement and with components missing: the kernels against the oracle, to rounding."""
    z = gappy(sonar.z[:40])
    a = make_filter("stcpf", **params).run(sonar.model, z, sonar.x0, sonar.P0, np.random.default_rng(7))
    b = oracle_filter("stcpf", **params).run(sonar.model, z, sonar.x0, sonar.P0, np.random.default_rng(7))
    assert a.diverged is False and b.diverged is False
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.P, b.P, rtol=1e-7, atol=1e-9)
    if "lambda_mean" in b.info:
        assert a.info["lambda_mean"] == pytest.approx(b.info["lambda_mean"], rel=1e-10)


@pytest.mark.parametrize("name,params", [("igwo-stcpf", {"estimate_at": "before"}), ("igwo-stcpf", {}),
                                         ("gwo-pf", {"estimate_at": "before"}), ("igwo-pf", {}),
                                         ("pso-cpf", {"estimate_at": "before"})])
@pytest.mark.slow
def test_compiled_swarm_masked_and_before_equal_the_oracle_at_first(sonar, name, params):
    """The swarm filters on gappy measurements and with the estimate before the move: the kernels agree
    with the oracle over the first steps (until rounding flips a leader among near-ties), and the
    elitism invariant holds (asserted on every move by the engine)."""
    z = gappy(sonar.z[:20])[:10]
    z[2, 2] = np.nan  # a masked step early, where the runs still agree
    a = make_filter(name, t_max=5, **params).run(sonar.model, z, sonar.x0, sonar.P0, np.random.default_rng(5))
    b = oracle_filter(name, t_max=5, **params).run(sonar.model, z, sonar.x0, sonar.P0, np.random.default_rng(5))
    assert a.diverged is False and b.diverged is False
    np.testing.assert_allclose(a.x[:6], b.x[:6], rtol=0, atol=1e-7)
    assert a.info["mean_fitness_gain"] > 0


class NoKernels(UNGM):
    def kernels(self):
        return None


class OwnLikelihood(UNGM):
    def loglik(self, z, x, k, mask=None):
        return super().loglik(z, x, k, mask)


@pytest.mark.parametrize("name", ["stcpf", "igwo-stcpf", "gwo-pf", "igwo-pf", "pso-cpf"])
def test_kernel_filters_refuse_a_model_without_kernels_in_one_line(name):
    rng = [np.random.default_rng(0)]
    flt = make_filter(name)
    with pytest.raises(ReplayError, match=f"^{name} needs a model with compiled kernels .*; DepthModel has none$"):
        flt.engine(DepthModel(), rng)
    with pytest.raises(ReplayError, match=f"^{name} needs a model with compiled kernels .*; NoKernels has none$"):
        flt.engine(NoKernels(), rng)
    with pytest.raises(ReplayError, match=f"^{name} needs the Gaussian likelihood .*; OwnLikelihood overrides loglik$"):
        flt.engine(OwnLikelihood(), rng)


def test_filters_without_kernels_run_on_any_model():
    """PSO-PF (bootstrap proposal, model.loglik, PSO) and the bootstrap STCPF need no kernels."""

    z = np.random.default_rng(0).normal(size=(6, 1))
    for model in (NoKernels(), OwnLikelihood()):
        for flt in (make_filter("pso-pf", n_particles=20, t_max=3), make_filter("stcpf", proposal="prior")):
            est = flt.run(model, z, np.zeros(1), np.eye(1), np.random.default_rng(1))
            assert est.diverged is False and np.isfinite(est.x).all()
    with pytest.raises(ReplayError, match="compiled"):
        make_filter("stcpf", compiled=False)


@pytest.mark.parametrize("threads", ["1", "2", "3"])
@pytest.mark.slow
def test_thread_count_does_not_change_the_numbers(sonar, monkeypatch, threads):
    def run():
        flt = make_filter("igwo-stcpf", n_particles=50, t_max=5)
        Z = np.stack([sonar.z[:15]] * 3)
        return flt.run_batch(sonar.model, Z, np.stack([sonar.x0] * 3), np.stack([sonar.P0] * 3),
                             [np.random.default_rng(r) for r in range(3)])

    monkeypatch.setattr(stcpf, "GRAIN_RUNS", 10)  # split even these few particles among the threads
    monkeypatch.setenv("REPLAY_THREADS", "1")
    ref = run()
    monkeypatch.setenv("REPLAY_THREADS", threads)
    for a, b in zip(run(), ref):
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)


@pytest.mark.parametrize("threads", ["1", "2", "3"])
@pytest.mark.slow
def test_one_run_on_openmp_threads_equals_one_thread(sonar, monkeypatch, threads):
    def run():
        return make_filter("igwo-stcpf", n_particles=60, t_max=4).run(sonar.model, sonar.z[:12], sonar.x0, sonar.P0,
                                                                       np.random.default_rng(4))

    monkeypatch.setattr(stcpf, "GRAIN", 7)
    monkeypatch.setenv("REPLAY_THREADS", "1")
    ref = run()
    monkeypatch.setenv("REPLAY_THREADS", threads)
    out = run()
    assert np.array_equal(out.x, ref.x) and np.array_equal(out.P, ref.P)


@pytest.mark.slow
def test_batched_compiled_runs_equal_one_by_one_exactly(sonar):
    flt = make_filter("igwo-stcpf", n_particles=40, t_max=6)
    Z, X0, P0 = np.stack([sonar.z[:12]] * 3), np.stack([sonar.x0] * 3), np.stack([sonar.P0] * 3)
    many = flt.run_batch(sonar.model, Z, X0, P0, [np.random.default_rng(10 + r) for r in range(3)])
    for r in range(3):
        one = flt.run(sonar.model, Z[r], X0[r], P0[r], np.random.default_rng(10 + r))
        assert np.array_equal(one.x, many[r].x)


@pytest.mark.slow
def test_factor_repairs_like_the_oracle():
    A = np.diag([4.0, 1.0, -1e-9])  # indefinite by a hair: eigenvalue floored
    L = np.empty((3, 3))
    assert compiled_util.factor(A.copy(), L) == 1
    ref, bad = batched_cholesky(A[None])
    np.testing.assert_allclose(L, ref[0], rtol=1e-12, atol=1e-12)
    assert bad[0]
    B = np.array([[4.0, 2.0], [2.0, 3.0]])
    assert compiled_util.factor(B, L[:2, :2]) == 0
    np.testing.assert_allclose(L[:2, :2], np.linalg.cholesky(B), rtol=1e-15)


@pytest.mark.slow
def test_swarm_kernel_keeps_the_elite_and_matches_the_oracle():
    """One swarm on a quadratic fitness (the random-walk model: h = identity on 3 states):
    the kernel and the oracle's gwo_optimize give the same wolves from the same 32-bit draws."""
    bound = stcpf.bound_kernels(RandomWalkPosition(np.eye(3), np.diag([1.0, 2.0, 4.0])).kernels())  # h = identity
    X = np.random.default_rng(1).normal(size=(30, 3)) * 3
    z = np.array([0.5, -1.0, 2.0])
    Ri = np.linalg.inv(np.diag([1.0, 2.0, 4.0]))
    raw = gwo.raw_draws([np.random.default_rng(2)], (8, 2, 3, 30, 3))[0]
    a = gwo.schedule(8, True)
    Xk, f, best = X.copy(), np.empty(30), np.empty(9)
    target = compiled_util.Fit(z, Ri, np.zeros(3, bool), np.zeros(3, bool), 0.0, 3)
    bound.swarm(np.zeros(0), Xk, np.zeros(3), target, np.arange(3), None, None, raw, compiled_util.Gwo(a, True, 1e-4, 1e-12),
                (f, best))
    assert np.all(np.diff(best) <= 0) and best[-1] < best[0]
    Xn, fn, bn = gwo_optimize(X, lambda Y: np.einsum("...i,ij,...j->...", z - Y, Ri, z - Y),
                              np.random.default_rng(2), t_max=8, improved=True)
    np.testing.assert_allclose(Xk, Xn, rtol=0, atol=1e-12)
    np.testing.assert_allclose(best, bn, rtol=1e-12)


@pytest.mark.slow
def test_swarm_kernel_moves_only_the_movable_components_and_adds_the_transition_term():
    """move_components=observed: a component outside ``mov`` keeps every wolf's value; fitness=posterior:
    the transition term of each wolf's own ancestor; both as the oracle's reading."""
    bound = stcpf.bound_kernels(RandomWalkPosition(np.eye(3), np.diag([1.0, 2.0, 4.0])).kernels())  # h = identity
    X = np.random.default_rng(1).normal(size=(30, 3)) * 3
    z = np.array([0.5, -1.0, 2.0])
    Ri = np.linalg.inv(np.diag([1.0, 2.0, 4.0]))
    fx = np.random.default_rng(3).normal(size=(30, 3))
    Qi = np.eye(3) * 0.5
    mov = np.array([True, True, False])
    raw = gwo.raw_draws([np.random.default_rng(2)], (8, 2, 3, 30, 3))[0]
    a = gwo.schedule(8, True)
    Xk, f, best = X.copy(), np.empty(30), np.empty(9)
    target = compiled_util.Fit(z, Ri, np.zeros(3, bool), np.zeros(3, bool), 0.0, 3)
    bound.swarm(np.zeros(0), Xk, np.zeros(3), target, np.arange(3), mov, (fx, Qi), raw,
                compiled_util.Gwo(a, True, 1e-4, 1e-12), (f, best))
    assert np.array_equal(Xk[:, 2], X[:, 2]) and not np.array_equal(Xk[:, :2], X[:, :2])

    def fit(Y):
        d = Y - fx
        return np.einsum("...i,ij,...j->...", z - Y, Ri, z - Y) + np.einsum("...i,ij,...j->...", d, Qi, d)

    Xn, fn, bn = gwo_optimize(X, fit, np.random.default_rng(2), t_max=8, improved=True, movable=mov[None])
    np.testing.assert_allclose(Xk, Xn, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f, fn, rtol=1e-12)


@pytest.mark.slow
def test_kernel_call_falls_back_when_argument_types_change():
    k = Kernel(compiled_util.estimate)
    X = np.random.default_rng(0).normal(size=(2, 5, 3))
    out = []
    for Xi in (X, np.asfortranarray(X), X[:, ::-1]):  # contiguous, then two layouts the first typing did not see
        logw = np.zeros((2, 5))
        x, P, w = np.empty((2, 3)), np.empty((2, 3, 3)), np.empty((2, 5))
        k(Xi, logw, np.array([False, False, True]), x, P, w)
        out.append(x)
    np.testing.assert_allclose(out[0], out[1], rtol=1e-14)
    np.testing.assert_allclose(out[0], out[2], rtol=1e-14)


def test_small_angle_sincos_matches_libm_to_rounding():
    for d in np.concatenate([np.linspace(-0.5, 0.5, 2001), [0.0, 1e-300, -0.49999999, 0.5000001, 3.0, -2.5]]):
        s, c = compiled_util.sincos_small(d)
        assert abs(s - np.sin(d)) <= 2.3e-16 * max(abs(np.sin(d)), 1e-300)
        assert abs(c - np.cos(d)) <= 1.2e-16


def test_circular_mean_of_points_across_the_wrap():
    """Points straddling +-pi: the mean is near pi, not near 0 (and equals atan2(sum sin, sum cos))."""
    x = np.array([np.pi - 0.05, 1.0])
    L = np.diag([0.2, 0.1])
    Y, mean, D = np.empty((4, 2)), np.empty(2), np.empty((4, 2))
    compiled_util.cubature_points(x, L, np.sqrt(2), Y)
    compiled_util.moments(Y, np.array([True, False]), mean, D)
    ang = Y[:, 0]
    assert mean[0] == pytest.approx(np.arctan2(np.sin(ang).sum(), np.cos(ang).sum()), abs=1e-15)
    assert abs(mean[0]) > 3.0 and mean[1] == pytest.approx(1.0)
    assert np.all(np.abs(D[:, 0]) < 0.3)  # deviations wrapped


def test_bound_kernels_are_cached_by_content(tmp_path, monkeypatch):
    """bind() writes compiled.py with the model's imports; the same kernels give the same file."""
    monkeypatch.setenv("REPLAY_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(copies, "_bound", {})
    m = RandomWalkPosition(np.eye(2), np.eye(2))
    mod = stcpf.bound_kernels(m.kernels())
    files = list((tmp_path / "kernels").glob("replay_compiled_*.py"))
    assert len(files) == 1 and mod.__file__ == str(files[0])
    text = files[0].read_text()
    assert "from replay.models.random_walk_kernels import identity as h" in text
    monkeypatch.setattr(copies, "_bound", {})
    assert stcpf.bound_kernels(m.kernels()).__file__ == mod.__file__


def test_bind_refuses_kernels_that_are_not_module_level():
    @numba.njit
    def local(x, p, out):
        out[:] = x

    with pytest.raises(ReplayError, match="module-level"):
        stcpf.bound_kernels((local, local, local, local))
