"""The bootstrap PF's compiled whole-run loop (replay.filters.pf_loop) gives the numbers of the
step-by-step engine bit for bit, and leaves every run's generator where the steps leave it."""
import numpy as np
import pytest

from replay.data import registry
from replay.filters import make_filter, pf_loop
from replay.models.random_walk import RandomWalkPosition
from replay.tasks import make_task
from replay.filters.compiled import loop_ready
from replay.util.seeds import rng_for

pytestmark = pytest.mark.slow  # compiles the loop (about 2 s) when numba's cache does not have it


@pytest.fixture(scope="module")
def sonar():
    task = make_task("sonar")
    pbs = [task.build(registry.load_frame("sim/auv-sonar", rng=rng_for(7, r, 0), steps=40), rng_for(7, r, 1))
           for r in range(3)]
    return pbs[0].model, np.stack([p.z for p in pbs]), np.stack([p.x0 for p in pbs]), np.stack([p.P0 for p in pbs])


def walk(missing_rows=True):
    """A 3-D random walk observed directly, 60 steps of 3 runs; some steps without measurement."""
    rng = np.random.default_rng(3)
    model = RandomWalkPosition(0.5 * np.eye(3), np.diag([1.0, 2.0, 0.5]))
    Z = np.cumsum(rng.normal(size=(3, 60, 3)), axis=1)
    if missing_rows:
        Z[0, 10:14] = np.nan
        Z[2, 30] = np.nan
    return model, Z, Z[:, 0] + 0.1, np.stack([np.eye(3)] * 3)


def both(flt, model, Z, X0, P0, monkeypatch):
    """(loop, steps, generator ends) for the same runs: the loop used, then the loop refused."""
    assert loop_ready(pf_loop.pf_run, pf_loop.PF_RUN, True)
    used, real = [], pf_loop.run
    monkeypatch.setattr(pf_loop, "run", lambda *a: used.append(real(*a)) or used[-1])
    gs = [np.random.default_rng(10 + m) for m in range(len(Z))]
    fast = flt.run_batch(model, Z, X0, P0, gs)
    fast_end = [g.random() for g in gs]
    monkeypatch.setattr(pf_loop, "run", lambda *a: None)
    gs = [np.random.default_rng(10 + m) for m in range(len(Z))]
    slow = flt.run_batch(model, Z, X0, P0, gs)
    return used, fast, slow, fast_end, [g.random() for g in gs]


@pytest.mark.parametrize("params", [{"n_particles": 150}, {"n_particles": 150, "roughening": 0.2},
                                    {"n_particles": 120, "ess_threshold": 0.3}])
def test_loop_equals_the_steps_on_the_sonar_model(sonar, params, monkeypatch):
    used, fast, slow, e1, e2 = both(make_filter("pf", **params), *sonar, monkeypatch)
    assert len(used) == 1 and isinstance(used[0], tuple)  # the loop ran
    for a, b in zip(fast, slow):
        assert np.isfinite(a.x).all()
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert a.info["resampled"] == b.info["resampled"]
        assert a.info["mean_ess"] == b.info["mean_ess"] and 1 <= a.info["mean_ess"] <= params["n_particles"]
        assert np.array_equal(a.info["nis_dof"], b.info["nis_dof"]) and np.isnan(a.info["nis"]).all()
    assert e1 == e2  # the generators were advanced by the same draws
    if params.get("ess_threshold", 1.0) < 1.0:
        assert 0 < fast[0].info["resampled"] < 40  # the threshold was exercised both ways


def test_steps_without_measurement_keep_the_weights(monkeypatch):
    model, Z, X0, P0 = walk()
    used, fast, slow, e1, e2 = both(make_filter("pf", n_particles=200, ess_threshold=0.5), model, Z, X0, P0,
                                    monkeypatch)
    assert isinstance(used[0], tuple)
    for a, b in zip(fast, slow):
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert a.info["resampled"] == b.info["resampled"]
    assert e1 == e2


def test_partly_missing_measurements_give_the_numbers_of_the_steps(monkeypatch):
    """A step that measures some components (run 1 at step 5, every run at steps 20-29: one
    component each) is weighted by those alone, with R restricted to them, in the loop too."""
    model, Z, X0, P0 = walk(missing_rows=False)
    Z[1, 5, 0] = np.nan
    Z[:, 20:25, 1:] = np.nan
    Z[:, 25:30, :2] = np.nan
    used, fast, slow, e1, e2 = both(make_filter("pf", n_particles=50), model, Z, X0, P0, monkeypatch)
    assert isinstance(used[0], tuple)  # the loop ran
    for a, b in zip(fast, slow):
        assert np.isfinite(a.x).all()
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert a.info["resampled"] == b.info["resampled"] == 60
    assert e1 == e2


class _VaryingWalk(RandomWalkPosition):
    """The random walk with a process noise that grows and a measurement noise per step."""

    def process_cov(self, k):
        return self.Q * (1.0 + 0.1 * k)

    def measurement_cov(self, k):
        return self.R * (1.0 + (k % 3))


def test_time_varying_noise_gives_the_numbers_of_the_steps(monkeypatch):
    _, Z, X0, P0 = walk()
    model = _VaryingWalk(0.5 * np.eye(3), np.diag([1.0, 2.0, 0.5]))
    Z[2, 40, 1] = np.nan
    used, fast, slow, e1, e2 = both(make_filter("pf", n_particles=60, roughening=0.1), model, Z, X0, P0, monkeypatch)
    assert isinstance(used[0], tuple)
    for a, b in zip(fast, slow):
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
    assert e1 == e2
    late = fast[0].P[-1].diagonal()  # the noise did change: the last spread is that of the larger Q
    model.process_cov = lambda k: model.Q
    const = make_filter("pf", n_particles=60, roughening=0.1).run_batch(model, Z, X0, P0,
                                                                         [np.random.default_rng(m) for m in range(3)])
    assert (late > const[0].P[-1].diagonal()).all()


def test_what_the_loop_does_not_compute_steps_in_python(monkeypatch):
    used, *_ = both(make_filter("pf", n_particles=50, resampling="multinomial"), *walk(), monkeypatch)
    assert used == [None]
    used, *_ = both(make_filter("wf-pf", n_particles=50), *walk(), monkeypatch)
    assert used == []  # another weighting: the engine does not ask for the loop


@pytest.mark.parametrize("name,params", [("pf", {"n_particles": 100, "roughening": 0.2}), ("ukf", {}), ("ekf", {})])
def test_the_loops_give_the_same_numbers_on_any_thread_count(sonar, name, params, monkeypatch):
    """Runs are split over threads in contiguous ranges, each run from its own generator: one
    thread or three give the same numbers bit for bit (the grain lowered so that 3 runs split)."""
    from replay.filters import kalman_loops as kk
    from replay.filters.compiled import loops

    for loop, sig in ((kk.sigma_run, kk.SIGMA_RUN), (kk.ekf_run, kk.EKF_RUN), (pf_loop.pf_run, pf_loop.PF_RUN)):
        assert loop_ready(loop, sig, True)
    monkeypatch.setattr(loops, "THREAD_WORK_US", 1e-9)
    out = {}
    for n in ("1", "3"):
        monkeypatch.setenv("REPLAY_THREADS", n)
        out[n] = make_filter(name, **params).run_batch(*sonar, [np.random.default_rng(m) for m in range(3)])
    for a, b in zip(out["1"], out["3"]):
        assert np.isfinite(a.x).all()
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert np.array_equal(a.info["nis"], b.info["nis"], equal_nan=True)


def test_any_bit_generator_gives_the_numbers_of_the_steps(monkeypatch):
    """numba draws with NumPy's algorithms from the generator's own bit generator: MT19937 and
    Philox streams too."""
    model, Z, X0, P0 = walk()
    flt = make_filter("pf", n_particles=80, roughening=0.1)
    assert loop_ready(pf_loop.pf_run, pf_loop.PF_RUN, True)
    used, real = [], pf_loop.run
    monkeypatch.setattr(pf_loop, "run", lambda *a: used.append(real(*a)) or used[-1])
    for bits in (np.random.MT19937, np.random.Philox):
        fast = flt.run_batch(model, Z, X0, P0, [np.random.Generator(bits(m)) for m in range(3)])
        monkeypatch.setattr(pf_loop, "run", lambda *a: None)
        slow = flt.run_batch(model, Z, X0, P0, [np.random.Generator(bits(m)) for m in range(3)])
        monkeypatch.setattr(pf_loop, "run", lambda *a: used.append(real(*a)) or used[-1])
        assert isinstance(used[-1], tuple)
        assert all(np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P) for a, b in zip(fast, slow))
