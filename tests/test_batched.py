"""Every filter runs over the Monte Carlo run axis: a batch of M runs equals M runs of one, bit for bit."""
import numpy as np
import pytest

from replay.data import registry
from replay.filters import make_filter
from replay.model import LinearGaussian, Model
from replay.tasks import make_task
from replay.util.linalg import cholesky
from replay.util.seeds import filter_rng, rng_for

RUNS = 4


@pytest.fixture(scope="module")
def sonar_problems():
    task = make_task("sonar")
    return [task.build(registry.load_frame("sim/auv-sonar", rng=rng_for(4, r, 0), steps=60), rng_for(4, r, 1))
            for r in range(RUNS)]


def _both(flt, problems, name):
    seq = [flt.run(p.model, p.z, p.x0, p.P0, filter_rng(4, r, name)) for r, p in enumerate(problems)]
    bat = flt.run_batch(problems[0].model, np.stack([p.z for p in problems]),
                        np.stack([p.x0 for p in problems]), np.stack([p.P0 for p in problems]),
                        [filter_rng(4, r, name) for r in range(len(problems))])
    return seq, bat


def _same(a, b):
    assert a.diverged_at == b.diverged_at
    assert np.array_equal(a.x, b.x, equal_nan=True) and np.array_equal(a.P, b.P, equal_nan=True)
    assert a.info.keys() == b.info.keys()
    for key, va in a.info.items():
        vb = b.info[key]
        if isinstance(va, np.ndarray) and va.dtype.kind == "f":
            assert np.array_equal(va, vb, equal_nan=True), key
        else:
            assert np.array_equal(va, vb), key


@pytest.mark.parametrize("name, params", [
    ("ekf", {}), ("ukf", {}), ("ckf", {}),
    ("pf", {"n_particles": 200, "ess_threshold": 0.5}),
    ("pf", {"n_particles": 200, "roughening": 0.5}),
    ("wf-pf", {"n_particles": 200}),
    ("stckf", {}), ("aukf", {}),  # written per run: the default engine loops over the runs
])
def test_batch_equals_one_by_one_bit_for_bit(sonar_problems, name, params):
    flt = make_filter(name, **params)
    seq, bat = _both(flt, sonar_problems, name)
    for a, b in zip(seq, bat):
        _same(a, b)
        assert not a.diverged
    assert not np.array_equal(seq[0].x, seq[1].x)
    if name in ("ekf", "ukf", "ckf"):
        assert all(np.isfinite(b.info["nis"]).all() and (b.info["nis_dof"] == 3).all() for b in bat)
    if name.endswith("pf"):
        assert all(b.info["resampled"] > 0 for b in bat)


class Turning(LinearGaussian):
    """Nonlinear, no Jacobians of its own: the EKF uses central differences (transposed arrays)."""

    x_angles = z_angles = (0,)

    def f(self, x, k):
        y = x.copy()
        y[..., 0] += 0.1 * np.sin(x[..., 1]) + 0.3
        return y

    F, H = Model.F, Model.H  # central differences


@pytest.mark.parametrize("name", ["ekf", "ukf", "pf"])
def test_numerical_jacobians_and_angles_bit_for_bit(name):
    model = Turning(np.eye(2), np.eye(2), np.diag([1e-3, 1e-2]), np.diag([0.01, 0.1]))
    Z = np.random.default_rng(6).standard_normal((3, 40, 2)) * 0.1 + np.array([3.0, 1.0])
    X0, P0 = np.tile([3.0, 1.0], (3, 1)), np.stack([np.diag([0.1, 0.1])] * 3)
    flt = make_filter(name, **({"n_particles": 64} if name == "pf" else {}))
    bat = flt.run_batch(model, Z, X0, P0, [np.random.default_rng(m) for m in range(3)])
    for m in range(3):
        _same(bat[m], flt.run(model, Z[m], X0[m], P0[m], np.random.default_rng(m)))
        assert not bat[m].diverged


def test_roughening_is_applied_in_batches(sonar_problems):
    """The batched PF used to skip roughening (issue 11): a batch now differs from the plain PF."""
    pbs = sonar_problems[:2]
    plain = _both(make_filter("pf", n_particles=200), pbs, "pf")[1]
    rough = _both(make_filter("pf", n_particles=200, roughening=0.5), pbs, "pf")[1]
    assert not np.array_equal(plain[0].x, rough[0].x)


def _linear():
    A, C = np.eye(2), np.eye(2)
    return LinearGaussian(A, C, 0.1 * np.eye(2), 0.5 * np.eye(2))


@pytest.mark.parametrize("name", ["kf", "ukf", "ckf", "pf"])
def test_missing_measurements_and_divergence_per_run(name):
    """Runs with different NaN patterns group correctly; a run whose prior breaks leaves the stack."""
    model = _linear()
    rng = np.random.default_rng(0)
    Z = rng.standard_normal((3, 20, 2))
    Z[0, 5] = np.nan
    Z[1, 7, 1] = np.nan
    X0 = np.zeros((3, 2))
    P0 = np.stack([np.eye(2), np.eye(2), np.eye(2)])
    P0[2] = [[1.0, 2.0], [2.0, 1.0]]  # not positive definite: a Cholesky factor fails at the start
    flt = make_filter(name, **({"n_particles": 100} if name == "pf" else {}))
    bat = flt.run_batch(model, Z, X0, P0, [np.random.default_rng(m) for m in range(3)])
    for m in range(2):
        _same(bat[m], flt.run(model, Z[m], X0[m], P0[m], np.random.default_rng(m)))
    if name != "pf":
        assert bat[1].info["nis_dof"][7] == 1 and bat[0].info["nis_dof"][5] == 0
        assert np.isnan(bat[0].info["nis"][5]) and np.isfinite(bat[1].info["nis"][7])
    assert bat[2].diverged_at == 0 and np.isnan(bat[2].x).all()
    if name != "kf":  # the EKF needs no factor of P; the others fail with a LinAlgError
        assert bat[2].info["error"].startswith("LinAlgError")


class Fragile(LinearGaussian):
    """h raises (as a numerical routine may) when the first state component passes 50, and the
    likelihood of the particle filters when the measurement does."""

    def h(self, x, k):
        if np.any(x[..., 0] > 50.0):
            raise FloatingPointError("boom")
        return super().h(x, k)

    def loglik(self, z, x, k, mask=None):
        if z[0] > 50.0:
            raise FloatingPointError("boom")
        return super().loglik(z, x, k, mask)


@pytest.mark.parametrize("name", ["ekf", "ukf", "pf", "wf-pf", "stckf"])
def test_exception_in_one_run_leaves_the_others_as_alone(name):
    model = Fragile(np.eye(2), np.eye(2), 0.1 * np.eye(2), 0.5 * np.eye(2))
    Z = np.random.default_rng(1).standard_normal((3, 30, 2))
    Z[1, 10:, 0] = 100.0  # run 1 walks past 50 and h raises for it
    X0, P0 = np.zeros((3, 2)), np.stack([np.eye(2)] * 3)
    flt = make_filter(name, **({"n_particles": 100} if name.endswith("pf") else {}))
    bat = flt.run_batch(model, Z, X0, P0, [np.random.default_rng(m) for m in range(3)])
    for m in (0, 2):
        alone = flt.run(model, Z[m], X0[m], P0[m], np.random.default_rng(m))
        _same(bat[m], alone)
        assert not alone.diverged
    k = bat[1].diverged_at
    assert k is not None and 10 <= k < 30 and bat[1].info["error"] == "FloatingPointError: boom"
    assert np.isfinite(bat[1].x[:k]).all() and np.isnan(bat[1].x[k:]).all()
    _same(bat[1], flt.run(model, Z[1], X0[1], P0[1], np.random.default_rng(1)))


def test_kalman_filter_equals_closed_form_for_every_run():
    """Static scalar state, unit measurements: P_k = 1 / (1/P0 + k/r), x_k = P_k (x0/P0 + sum z / r)."""
    r = 0.5
    model = LinearGaussian([[1.0]], [[1.0]], [[0.0]], [[r]])
    M, n = 3, 25
    Z = np.random.default_rng(2).standard_normal((M, n, 1)) + np.array([1.0, -2.0, 4.0])[:, None, None]
    X0 = np.array([[0.0], [1.0], [-1.0]])
    P0 = np.array([[[1.0]], [[4.0]], [[0.25]]])
    for name in ("kf", "ekf", "ukf", "ckf"):
        est = make_filter(name).run_batch(model, Z, X0, P0, [None] * M)
        for m in range(M):
            k = np.arange(1, n + 1)
            Pk = 1.0 / (1.0 / P0[m, 0, 0] + k / r)
            xk = Pk * (X0[m, 0] / P0[m, 0, 0] + np.cumsum(Z[m, :, 0]) / r)
            np.testing.assert_allclose(est[m].P[:, 0, 0], Pk, rtol=1e-12)
            np.testing.assert_allclose(est[m].x[:, 0], xk, rtol=1e-11, atol=1e-12)
            # NIS: y^2 / S with y = z_k - x_{k-1}, S = P_{k-1} + r
            Pprev = np.r_[P0[m, 0, 0], Pk[:-1]]
            xprev = np.r_[X0[m, 0], xk[:-1]]
            np.testing.assert_allclose(est[m].info["nis"], (Z[m, :, 0] - xprev) ** 2 / (Pprev + r), rtol=1e-10)


def test_divergence_is_reported_per_run_not_raised():
    model = LinearGaussian(np.eye(2) * 1e200, np.eye(2), np.eye(2), np.eye(2))
    Z = np.ones((2, 20, 2))
    P0 = np.stack([np.eye(2), np.eye(2)])
    for name in ("ekf", "ukf"):
        with np.errstate(all="ignore"):
            est = make_filter(name).run_batch(model, Z, np.ones((2, 2)), P0, [None, None])
        for e in est:
            assert e.diverged and e.diverged_at < 20 and np.isnan(e.x[e.diverged_at:]).all()
            assert np.isfinite(e.x[:e.diverged_at]).all() and np.isnan(e.step_seconds[e.diverged_at:]).all()


def test_stacked_linear_algebra_equals_one_matrix():
    """Cholesky (LAPACK) and the compiled gain/NIS, correction and sigma points: each matrix of a
    stack gets the numbers it gets alone, bit for bit, and the numbers of the algebra to 1e-12."""
    from replay.filters.kalman import gain_nis
    from replay.filters.sigma import correct, sigma_points

    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 6, 11):
        A = rng.standard_normal((5, n, n))
        S = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(n)
        Pxz, y = rng.standard_normal((5, n + 2, n)), rng.standard_normal((5, n))
        P = rng.standard_normal((5, n + 2, n + 2))
        P = P @ np.swapaxes(P, 1, 2) + 0.1 * np.eye(n + 2)
        x, xi = rng.standard_normal((5, n + 2)), rng.standard_normal((2 * n + 5, n + 2))
        L, (K, nis) = cholesky(S), gain_nis(S, Pxz, y)
        xc, Pc, nc = correct(x, P + 10 * np.eye(n + 2), y, S, Pxz, (0,))
        X, dev = sigma_points(x, P, xi)
        for m in range(5):
            for one in (lambda a: a[m:m + 1], lambda a: a[m][None]):  # a stack of one
                assert np.array_equal(cholesky(one(S))[0], L[m])
            assert np.array_equal(cholesky(S[m]), L[m])
            Km, nm = gain_nis(S[m], Pxz[m], y[m])
            assert np.array_equal(Km, K[m]) and nm == nis[m]
            c1 = correct(x[m], P[m] + 10 * np.eye(n + 2), y[m], S[m], Pxz[m], (0,))
            assert all(np.array_equal(a, b) for a, b in zip(c1, (xc[m], Pc[m], nc[m])))
            assert all(np.array_equal(a, b) for a, b in zip(sigma_points(x[m], P[m], xi), (X[m], dev[m])))
        Si = np.linalg.inv(S)
        np.testing.assert_allclose(L @ np.swapaxes(L, 1, 2), S, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(K, Pxz @ Si, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(nis, np.einsum("mi,mij,mj->m", y, Si, y), rtol=1e-9)
        Kx = Pxz @ Si
        want = x + np.einsum("mij,mj->mi", Kx, y)
        want[:, 0] = (want[:, 0] + np.pi) % (2 * np.pi) - np.pi
        np.testing.assert_allclose(xc, want, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(Pc, P + 10 * np.eye(n + 2) - Kx @ np.swapaxes(Pxz, 1, 2), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(dev, xi @ np.swapaxes(np.linalg.cholesky(P), 1, 2), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(X, x[:, None] + dev, rtol=0, atol=0)
    bad = np.stack([np.eye(2), [[1.0, 2.0], [2.0, 1.0]]])
    for f in (lambda: cholesky(bad), lambda: cholesky(bad[1:]), lambda: gain_nis(bad, np.ones((2, 3, 2)), np.ones((2, 2))),
              lambda: sigma_points(np.zeros((2, 2)), bad, np.eye(2))):
        with pytest.raises(np.linalg.LinAlgError):
            f()


def test_compiled_kernels_equal_their_python_source():
    """The compiled Kalman kernels and their un-jitted py_func (the readable source) agree to 1e-12."""
    from replay.filters import kalman_kernels as kernels

    rng = np.random.default_rng(8)
    A = rng.standard_normal((3, 3, 3))
    S = A @ np.swapaxes(A, 1, 2) + 0.5 * np.eye(3)
    Pxz, y = rng.standard_normal((3, 6, 3)), rng.standard_normal((3, 3))
    P0 = rng.standard_normal((3, 6, 6))
    P0 = P0 @ np.swapaxes(P0, 1, 2) + 20 * np.eye(6)
    x0 = rng.standard_normal((3, 6)) * 4
    mask = np.array([0, 0, 0, 0, 1, 1], bool)
    out = []
    for fun in (kernels.kalman_correct, kernels.kalman_correct.py_func):
        x, P, nis = x0.copy(), P0.copy(), np.empty(3)
        assert fun(x, P, y, S, Pxz, mask, nis) == -1
        out.append((x, P, nis))
    for a, b in zip(*out):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    assert (np.abs(out[0][0][:, 4:]) <= np.pi).all()

@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf"])
def test_fast_path_equals_the_readable_reference(sonar_problems, name, monkeypatch):
    """The Kalman family's compiled steps (replay.filters.kalman_kernels, replay.util.kernels) equal
    their un-jitted Python (tests/pure.py) over whole runs, and the fused sigma-point engine
    equals the per-run functions predict / innovation / correct (the per-run State API)."""
    from pure import pure
    from replay.filters import kalman_kernels
    from replay.util import kernels

    pbs = sonar_problems[:3]
    Z = np.stack([pb.z for pb in pbs])[:, :40]
    Z[1, 5:9, 2] = np.nan  # one run misses its azimuth for four steps: grouped updates
    X0, P0 = np.stack([pb.x0 for pb in pbs]), np.stack([pb.P0 for pb in pbs])
    flt = make_filter(name)

    def run(f):
        return [e.x for e in f.run_batch(pbs[0].model, Z, X0, P0, [None] * 3)]

    fast = run(flt)
    assert all(np.isfinite(x).all() for x in fast)
    if name != "ekf":  # the per-run API: a subclass overriding one per-run method runs it
        per_run = type("PerRun", (type(flt),), {"predict": lambda self, s, k: type(flt).predict(self, s, k)})()
        assert all(np.array_equal(a, b) for a, b in zip(fast, run(per_run)))
    for mod in (kalman_kernels, kernels):
        for attr in dir(mod):
            if hasattr(getattr(mod, attr), "py_func"):
                monkeypatch.setattr(mod, attr, pure(getattr(mod, attr)))
    ref = run(flt)
    for a, b in zip(fast, ref):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0)


@pytest.mark.slow  # compiles the two run loops when numba's cache lacks them (~12 s, once)
@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf"])
def test_whole_run_loop_equals_the_step_by_step_engine(sonar_problems, name, monkeypatch):
    """With every measurement present the engine runs all steps in one compiled loop
    (kalman_loops.sigma_run / ekf_run, the model's kernels as first-class functions); it
    gives the numbers of the step-by-step engine bit for bit, NIS included."""
    from replay.filters import kalman
    from replay.filters import kalman_loops
    from replay.filters.compiled import loop_ready

    for loop, sig in ((kalman_loops.sigma_run, kalman_loops.SIGMA_RUN),
                      (kalman_loops.ekf_run, kalman_loops.EKF_RUN)):
        assert loop_ready(loop, sig, True)
    pbs = sonar_problems[:3]
    Z = np.stack([pb.z for pb in pbs])
    X0, P0 = np.stack([pb.x0 for pb in pbs]), np.stack([pb.P0 for pb in pbs])
    flt = make_filter(name)
    used, real = [], kalman.run_kernels
    monkeypatch.setattr(kalman, "run_kernels", lambda *a: used.append(real(*a)) or used[-1])
    fast = flt.run_batch(pbs[0].model, Z, X0, P0, [None] * 3)
    one = flt.run(pbs[1].model, Z[1], X0[1], P0[1])
    assert len(used) == 2 and all(isinstance(u, tuple) for u in used)  # the loop ran, both times
    monkeypatch.setattr(kalman, "run_kernels", lambda *a: None)  # no loop: step by step
    slow = flt.run_batch(pbs[0].model, Z, X0, P0, [None] * 3)
    for a, b in zip(fast, slow):
        assert np.isfinite(a.x).all()
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert np.array_equal(a.info["nis"], b.info["nis"])
    assert np.array_equal(one.x, slow[1].x)


@pytest.mark.slow  # compiles the two run loops when numba's cache lacks them (~12 s, once)
@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf"])
def test_whole_run_loop_skips_the_update_of_missing_rows(sonar_problems, name, monkeypatch):
    """Rows missing for every run (a gap in a log) are predicted only, in the loop as in the steps
    (NIS NaN, dof 0 there); a gap in one run only, or in one component, leaves the loop out."""
    from replay.filters import kalman

    pbs = sonar_problems[:3]
    Z = np.stack([pb.z for pb in pbs])
    Z[:, 5:9] = np.nan
    Z[:, 20] = np.nan
    X0, P0 = np.stack([pb.x0 for pb in pbs]), np.stack([pb.P0 for pb in pbs])
    flt = make_filter(name)
    used, real = [], kalman.run_kernels
    monkeypatch.setattr(kalman, "run_kernels", lambda *a: used.append(real(*a)) or used[-1])
    fast = flt.run_batch(pbs[0].model, Z, X0, P0, [None] * 3)
    Z1 = Z.copy()
    Z1[1, 30, 0] = np.nan
    flt.run_batch(pbs[0].model, Z1, X0, P0, [None] * 3)
    assert isinstance(used[0], tuple) and used[1] is None
    monkeypatch.setattr(kalman, "run_kernels", lambda *a: None)
    slow = flt.run_batch(pbs[0].model, Z, X0, P0, [None] * 3)
    for a, b in zip(fast, slow):
        assert np.isfinite(a.x).all()
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert np.array_equal(a.info["nis"], b.info["nis"], equal_nan=True)
        assert np.array_equal(a.info["nis_dof"], b.info["nis_dof"]) and a.info["nis_dof"][6] == 0
        assert np.isnan(a.info["nis"][20]) and np.isfinite(a.info["nis"][21])


@pytest.mark.slow  # compiles the two run loops when numba's cache lacks them (~12 s, once)
@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf"])
def test_whole_run_loop_updates_the_measured_components_only(sonar_problems, name, monkeypatch):
    """Components missing at a step for every run (sensors at their own rates, as in the fusion
    task): the loop updates with the measured ones (R, angles restricted to them), as the steps
    do, bit for bit; NIS with their count as degrees of freedom."""
    pbs = sonar_problems[:3]
    Z = np.stack([pb.z for pb in pbs])
    Z[:, 5:9, 0] = np.nan  # range missing: elevation and azimuth (an angle) only
    Z[:, 12:15, 1:] = np.nan
    Z[:, 20] = np.nan
    X0, P0 = np.stack([pb.x0 for pb in pbs]), np.stack([pb.P0 for pb in pbs])
    used, fast, slow = loop_then_steps(make_filter(name), pbs[0].model, Z, X0, P0, monkeypatch)
    assert isinstance(used[0], tuple)
    for a, b in zip(fast, slow):
        assert np.isfinite(a.x).all()
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert np.array_equal(a.info["nis"], b.info["nis"], equal_nan=True)
        assert np.array_equal(a.info["nis_dof"], b.info["nis_dof"])
        assert list(a.info["nis_dof"][[4, 5, 12, 20]]) == [3, 2, 1, 0]


def loop_then_steps(flt, model, Z, X0, P0, monkeypatch):
    """(what run_kernels returned, the runs with the loop allowed, the runs stepped in Python)."""
    from replay.filters import kalman

    used, real = [], kalman.run_kernels
    monkeypatch.setattr(kalman, "run_kernels", lambda *a: used.append(real(*a)) or used[-1])
    fast = flt.run_batch(model, Z, X0, P0, [None] * len(Z))
    monkeypatch.setattr(kalman, "run_kernels", lambda *a: None)
    return used, fast, flt.run_batch(model, Z, X0, P0, [None] * len(Z))
