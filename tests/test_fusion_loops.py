"""The fusion task's filters run in the compiled whole-run loops (every sensor at its own rate: a
few components measured per step, Q and R per step) and give the numbers of the step-by-step
engines bit for bit, with a filter's noise scales too."""
import copy

import numpy as np
import pytest

import replay
from replay.filters import kalman, make_filter, pf as pf_module, sigma
from replay.filters.compiled import cov_stacks, loop_ready
from replay.filters.noise_params import apply
from replay.models.kinematic import Kinematic2D

ENGINES = {"ekf": kalman.EKFEngine, "ukf": sigma.SigmaEngine, "ckf": sigma.SigmaEngine, "pf": pf_module.PFEngine}


def kinematic(steps=50):
    rng = np.random.default_rng(4)
    dt = rng.uniform(0.0, 0.05, steps)
    R = rng.uniform(0.01, 1.0, (steps, 3))
    return Kinematic2D(dt, np.array([0.01, 0.01, 0.01, 0.5, 0.5, 0.5]), [0, 1, 5], [1.0, 1.0, 1.0], [], R)


def test_stacks_of_the_kinematic_model_are_its_covariances_of_every_step():
    m = kinematic()
    Q, R = cov_stacks(m, 50)
    assert np.array_equal(Q, [m.process_cov(k) for k in range(50)])
    assert np.array_equal(R, [m.measurement_cov(k) for k in range(50)])
    assert Q[0, 0, 0] > 0 and Q[0, 0, 1] == 0 and cov_stacks(m, 7)[1].shape == (7, 3, 3)
    flt = make_filter("ekf", q_scale=3.0, r_scale=0.2)
    scaled, _ = apply(flt, m, np.eye(6)[None])
    Qs, Rs = cov_stacks(scaled, 50)  # the scales reach the stacks
    assert np.array_equal(Qs, [scaled.process_cov(k) for k in range(50)]) and np.allclose(Qs, 3.0 * Q, rtol=1e-15)
    assert np.array_equal(Rs, [scaled.measurement_cov(k) for k in range(50)]) and np.allclose(Rs, 0.2 * R, rtol=1e-15)
    other = copy.copy(m)
    other.process_cov = lambda k: m.process_cov(k) * 5.0  # a one-step method replaced alone: it is used
    assert np.array_equal(cov_stacks(other, 50)[0], [m.process_cov(k) * 5.0 for k in range(50)])


@pytest.fixture(scope="module")
def auv_bag():
    ev = replay.evaluate("sim/auv-bag", task="fusion", filters=["ekf"], runs=1, first=600)
    return ev.results[0].records[0].problem


@pytest.mark.slow  # compiles the run loops when numba's cache lacks them
@pytest.mark.parametrize("name,params", [("ekf", {"q_scale": 2.0}), ("ukf", {"r_scale": 0.5}), ("ckf", {}),
                                         ("pf", {"n_particles": 80, "q_scale": 0.5, "roughening": 0.1})])
def test_fusion_loops_equal_the_steps(auv_bag, name, params, monkeypatch):
    from replay.filters import kalman_loops as kk, pf_loop

    for loop, sig in ((kk.sigma_run, kk.SIGMA_RUN), (kk.ekf_run, kk.EKF_RUN), (pf_loop.pf_run, pf_loop.PF_RUN)):
        assert loop_ready(loop, sig, True)
    pb, M = auv_bag, 2
    fin = np.isfinite(pb.z)
    assert 0 < fin.sum(axis=1).min() < fin.shape[1] and len(np.unique(fin, axis=0)) > 2  # partial steps
    flt = make_filter(name, **params)
    model, P0 = apply(flt, pb.model, np.stack([pb.P0] * M))
    args = (model, np.stack([pb.z] * M), np.stack([pb.x0] * M), P0)
    engine = ENGINES[name]
    used, real = [], engine.run_all
    monkeypatch.setattr(engine, "run_all", lambda self, Z, f: used.append(real(self, Z, f)) or used[-1])
    fast = flt.run_batch(*args, [np.random.default_rng(m) for m in range(M)])
    assert isinstance(used[0], tuple)  # the loop ran
    monkeypatch.setattr(engine, "run_all", lambda self, Z, f: None)
    slow = flt.run_batch(*args, [np.random.default_rng(m) for m in range(M)])
    for a, b in zip(fast, slow):
        assert np.isfinite(a.x).all() and not a.diverged
        assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert np.array_equal(a.info["nis"], b.info["nis"], equal_nan=True)
        assert np.array_equal(a.info["nis_dof"], b.info["nis_dof"])
