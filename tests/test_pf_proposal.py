"""The particle filter's locally optimal proposal (replay.filters.particles.propose; Doucet,
Godsill & Andrieu 2000) on measurements that select state components (the fusion task's
kinematic models): its moments and predictive likelihood against the closed form, the
compiled loop against the steps bit for bit, and where it is refused."""
import math

import numpy as np
import pytest

from replay.filters import make_filter, particles, pf_loop
from replay.filters.compiled import loop_ready
from replay.models.kinematic import Kinematic2D
from replay.models.random_walk import RandomWalkPosition
from replay.util.errors import ReplayError


def test_one_component_moments_and_likelihood_are_the_kalman_update():
    """Prior mean m = 2, var 0.5^2; z = -1.2 of -x (sign -1), R = 0.1: posterior var
    1 / (1/0.25 + 1/0.1) = 0.0714..., mean (2/0.25 + 1.2/0.1) * var = 1.4286; the weight
    factor log N(z; -2, 0.35) for every particle (they share the prior mean)."""
    N = 200_000
    Y = np.tile([2.0, 7.0], (N, 1))
    ll = np.zeros(N)
    sel = np.array([1, 0], np.int64)
    g = np.random.default_rng(1)
    particles.propose(Y, np.array([0.5, 0.3]), np.array([-1.2]), sel, np.array([0], np.int64), np.array([-1.0]),
                      np.array([0.1]), np.zeros(1, np.bool_), ll, g)
    var = 1.0 / (1 / 0.25 + 1 / 0.1)
    assert np.allclose(ll, -0.5 * (0.8**2 / 0.35 + math.log(2 * math.pi * 0.35)), rtol=0, atol=1e-12)
    assert abs(Y[:, 0].mean() - (2 / 0.25 + 1.2 / 0.1) * var) < 4 * math.sqrt(var / N)
    assert abs(Y[:, 0].var() / var - 1) < 0.02
    assert abs(Y[:, 1].mean() - 7.0) < 4 * 0.3 / math.sqrt(N) and abs(Y[:, 1].std() / 0.3 - 1) < 0.01


def test_no_measurement_is_the_bootstrap_draw():
    Y0 = np.random.default_rng(0).normal(size=(50, 3))
    a, b = Y0.copy(), Y0.copy()
    ll = np.full(50, 3.0)
    particles.propose(a, np.array([0.1, 0.2, 0.3]), np.zeros(1), np.zeros(2, np.int64), np.zeros(1, np.int64),
                      np.ones(1), np.ones(1), np.zeros(1, np.bool_), ll, np.random.default_rng(5))
    particles.perturb(b, np.array([0.1, 0.2, 0.3]), np.random.default_rng(5))
    assert np.array_equal(a, b) and (ll == 3.0).all()


def test_two_sensors_of_one_state_are_one_joint_update():
    """Two measurements of one component at a step (odometry and gyro rates): sequential
    updates give the joint posterior var 1/(1/1 + 1/0.5 + 1/0.25) and the joint predictive."""
    N = 100_000
    Y = np.zeros((N, 1))
    ll = np.zeros(N)
    particles.propose(Y, np.ones(1), np.array([1.0, 2.0]), np.array([2, 0, 1], np.int64), np.zeros(2, np.int64),
                      np.ones(2), np.array([0.5, 0.25]), np.zeros(2, np.bool_), ll, np.random.default_rng(2))
    S = np.array([[1.5, 1.0], [1.0, 1.25]])  # cov of (z1, z2) = 1 + diag(R)
    z = np.array([1.0, 2.0])
    joint = -0.5 * (z @ np.linalg.solve(S, z) + math.log(np.linalg.det(S)) + 2 * math.log(2 * math.pi))
    assert abs(ll[0] - joint) < 1e-12
    var = 1 / (1 + 2 + 4)
    assert abs(Y.var() / var - 1) < 0.02 and abs(Y.mean() - var * (2 + 8)) < 4 * math.sqrt(var / N)


def kinematic(steps=80, runs=3, held=False):
    """A 2-D kinematic model measuring u, v, r (some steps only r, some nothing) and yaw; ``held``:
    the first step's dt = 0 (the fusion task's steps before the first message)."""
    rng = np.random.default_rng(4)
    dt = np.full(steps, 0.1)
    dt[0] = 0.0 if held else dt[0]
    R = np.tile([0.01, 0.01, 0.02, 0.05], (steps, 1)) * (1 + (np.arange(steps) % 3))[:, None]
    model = Kinematic2D(dt, np.array([0.01, 0.01, 0.01, 0.5, 0.5, 0.5]), [3, 4, 5, 2], [1, 1, 1, 1], [3], R)
    Z = np.empty((runs, steps, 4))
    Z[..., 0], Z[..., 1], Z[..., 2] = 1.0, 0.0, 0.1
    Z[..., 3] = 0.1 * np.arange(steps) * 0.1
    Z += 0.05 * rng.normal(size=Z.shape)
    Z[:, :, 3] = np.where(np.arange(steps) % 10 == 0, Z[:, :, 3], np.nan)
    Z[min(1, runs - 1), 20:30, :2] = np.nan
    Z[:, 40:45] = np.nan
    X0 = np.zeros((runs, 6))
    return model, Z, X0, np.stack([np.eye(6) * 0.1] * runs)


@pytest.mark.slow  # compiles the loop when numba's cache does not have it
@pytest.mark.parametrize("held", [False, True])
def test_loop_equals_the_steps_with_the_optimal_proposal(monkeypatch, held):
    model, Z, X0, P0 = kinematic(held=held)
    assert loop_ready(pf_loop.pf_run, pf_loop.PF_RUN, True)
    used, real = [], pf_loop.run
    flt = make_filter("pf", n_particles=200, roughening=0.1)
    monkeypatch.setattr(pf_loop, "run", lambda *a: used.append(real(*a)) or used[-1])
    gs = [np.random.default_rng(10 + m) for m in range(len(Z))]
    fast = flt.run_batch(model, Z, X0, P0, gs)
    e1 = [g.random() for g in gs]
    monkeypatch.setattr(pf_loop, "run", lambda *a: None)
    gs = [np.random.default_rng(10 + m) for m in range(len(Z))]
    slow = flt.run_batch(model, Z, X0, P0, gs)
    assert isinstance(used[0], tuple) and e1 == [g.random() for g in gs]
    for a, b in zip(fast, slow):
        assert np.isfinite(a.x).all() and np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
    boot = make_filter("pf", n_particles=200, roughening=0.1, proposal="bootstrap").run_batch(
        model, Z, X0, P0, [np.random.default_rng(10 + m) for m in range(len(Z))])
    assert not np.array_equal(boot[0].x, fast[0].x)  # the proposal did change the draws


def test_optimal_proposal_weights_stay_even_where_the_bootstrap_collapses():
    """Velocity measured with sd 0.03 against a predicted spread 0.22 (test1.bag's odometry):
    the bootstrap keeps about 2 % of its particles per step (mean ESS), the optimal proposal
    nearly all of them."""
    steps = 60
    model = Kinematic2D(np.full(steps, 0.1), np.array([0.01, 0.01, 0.01, 0.5, 0.5, 0.5]), [3, 4, 5], [1, 1, 1],
                        [], np.tile([0.001, 0.001, 0.03], (steps, 1)))
    Z = np.tile([1.0, 0.0, 0.1], (1, steps, 1))
    X0, P0 = np.zeros((1, 6)), np.eye(6)[None] * 0.1
    ess = {}
    for prop in ("bootstrap", "optimal"):
        r = make_filter("pf", n_particles=500, proposal=prop).run_batch(model, Z, X0, P0, [np.random.default_rng(0)])
        ess[prop] = r[0].info["mean_ess"] / 500
    assert ess["bootstrap"] < 0.1 and ess["optimal"] > 0.8, ess


def test_optimal_refused_where_it_does_not_apply():
    model = RandomWalkPosition(0.5 * np.eye(2), np.eye(2))
    Z = np.zeros((1, 5, 2))
    with pytest.raises(ReplayError, match=r'pf: proposal = "optimal" needs a model .*RandomWalkPosition'):
        make_filter("pf", n_particles=10, proposal="optimal").run_batch(model, Z, np.zeros((1, 2)),
                                                                     np.eye(2)[None], [np.random.default_rng(0)])
    auto = make_filter("pf", n_particles=10).run_batch(model, Z, np.zeros((1, 2)), np.eye(2)[None],
                                                       [np.random.default_rng(0)])
    boot = make_filter("pf", n_particles=10, proposal="bootstrap").run_batch(model, Z, np.zeros((1, 2)),
                                                                          np.eye(2)[None], [np.random.default_rng(0)])
    assert np.array_equal(auto[0].x, boot[0].x)  # auto: the bootstrap where the optimal does not apply


@pytest.mark.parametrize("proposal", ["bootstrap", "optimal"])
def test_gates_reject_the_injected_outliers_with_either_proposal(proposal):
    """tests/test_fusion_noise.py's 12 outlying fixes among 60: both proposals reject exactly
    those (the optimal one judges f(x^i) with Q added to the particles' spread)."""
    from test_fusion_noise import _gated_problem

    model, Z, x0, P0, truth, n_bad = _gated_problem(5.0)
    r = make_filter("pf", n_particles=500, proposal=proposal).run(model, Z, x0, P0, np.random.default_rng(0))
    assert r.info["rejected"] == {"gps.position": n_bad}
    assert np.sqrt(np.mean(np.sum((r.x[:, :2] - truth) ** 2, axis=1))) < 1.5


def test_a_held_first_step_draws_from_the_prior_updated_by_the_first_message():
    """dt = 0 at the first step (f the identity there): the first proposal carries the prior P0,
    so a first message far sharper than P0 (velocity sd 0.01 against 1 m/s) leaves every particle
    its weight (ESS = N at that step) instead of the one particle nearest it, and the particles'
    u is the Kalman update of the prior: mean 1.5 * 1 / (1 + 1e-4), sd 0.01."""
    model, Z, X0, P0 = kinematic(steps=1, runs=1, held=True)
    Z[:] = np.nan
    Z[0, 0, 0] = 1.5
    model.R_steps[:, 0] = 1e-4
    P0 = np.eye(6)[None] * 1.0
    from replay.filters.pf import PFEngine

    eng = PFEngine(make_filter("pf", n_particles=4000), model, [np.random.default_rng(0)])
    eng.start(X0, P0)
    assert eng.sd0 is not None and (eng.X == 0).all()
    eng.propose(0, Z[:, 0], np.isfinite(Z[:, 0]))
    assert np.allclose(eng.w, 1 / 4000, rtol=1e-12)
    u = eng.X[0, :, 3]
    assert abs(u.mean() - 1.5 / (1 + 1e-4)) < 4 * 0.01 / np.sqrt(4000) and abs(u.std() / 0.01 - 1) < 0.05
    eng2 = PFEngine(make_filter("pf", n_particles=4000), kinematic(steps=1, runs=1)[0], [np.random.default_rng(0)])
    eng2.start(X0, P0)
    assert eng2.sd0 is None  # dt > 0 at the first step: the particles drawn from P0 as before
