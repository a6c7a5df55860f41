"""One home per numeric step (issue 26, item 1): each caller uses the one definition.

The angle wrap (``replay.util.angles.wrap``, compiled as ``replay.util.kernels.wrap_angle``), the
Gaussian log-density (``replay.util.kernels.gauss_logpdf``), ESS, roughening and the propagation
noise (``replay.filters.particles``), the fading factor (``compiled_util.fading_factor``) and the
cubature step (``compiled.cubature_step``): the former call sites give the same bits as the one
definition on random inputs, and the known values of the fading factor and the cubature step.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from replay.filters import make_filter, particles, pf, pf_loop
from replay.filters.p002 import compiled_util, stack, stcpf
from replay.models import kinematic2_kernels, kinematic3_kernels
from replay.util import angles, kernels

from oracle_p002 import fading_factor as oracle_fading
from oracle_p002 import next_V
from replay.filters.p002 import compiled
from replay import model
from replay.scoring import likelihood
from replay.models import noise
from replay.models.ungm import UNGM
from replay.filters.p002 import stckf
from replay.models.random_walk import RandomWalkPosition
from replay.filters.p002.stcpf import bound_kernels as bind
import json
import tempfile
from pathlib import Path
from pure import pure
from replay.sim.auv_sonar import make_frame
from replay.tasks import make_task


def _angles(g, n=4000):
    a = g.standard_normal(n) * 10.0 ** g.integers(-3, 7, n)
    edge = [0.0, -0.0, math.pi, -math.pi, 3.0, -3.0, 3.2, 2 * math.pi, -2 * math.pi, 1e15, np.nan, np.inf, -np.inf]
    return np.concatenate([a, edge])


def _same(a, b):
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


# --- the angle wrap ---------------------------------------------------------------------------
@np.errstate(invalid="ignore")  # inf - inf: NaN, as it should
def test_every_angle_wrap_is_the_one_formula_bit_for_bit():
    a = _angles(np.random.default_rng(0))
    ref = a - np.floor(a * (1.0 / (2.0 * np.pi)) + 0.5) * (2.0 * np.pi)
    assert _same(angles.wrap(a), ref)
    assert _same([angles.wrap(float(v)) for v in a], ref)  # numbers
    assert _same([kernels.wrap_angle(v) for v in a], ref)  # compiled
    assert _same([kernels.wrap_angle.py_func(v) for v in a], ref)  # its text is angles.wrap's
    assert kernels.wrap_angle.py_func is angles.wrap
    v = a.copy()
    kernels.wrap(v, np.ones(len(v), bool))
    assert _same(v, ref)
    X = a[: 4000].reshape(-1, 4).copy()
    mask = np.array([True, False, True, True])
    expect = X.copy()
    expect[:, mask] = ref[: 4000].reshape(-1, 4)[:, mask]
    for wrapped in (angles.wrap_components(X.copy(), (0, 2, 3)), stack.wrap_inplace(X.copy(), (0, 2, 3)),
                    stack.wrap_inplace(np.asfortranarray(X), (0, 2, 3))):  # compiled rows, numpy fallback
        assert _same(wrapped, expect)
    rows = X.copy()
    compiled_util.wrap_rows(rows, mask)
    assert _same(rows, expect)
    one = X[5].copy()
    assert _same(angles.wrap_components(one, (0, 2, 3)), expect[5])  # one vector: the scalar loop
    # the models' kernels wrap with the same function
    assert kinematic3_kernels._wrap is kernels.wrap_angle and kinematic2_kernels.wrap_angle is kernels.wrap_angle


def test_cubature_moments_wrap_with_the_one_formula():
    """compiled_util.moments: circular mean of cubature points across +-pi, deviations wrapped."""
    g = np.random.default_rng(1)
    Y = np.column_stack([np.pi - 0.05 + 0.1 * g.random(8), g.standard_normal(8)])
    mean, D = np.empty(2), np.empty((8, 2))
    compiled_util.moments(Y, np.array([True, False]), mean, D)
    assert -np.pi <= mean[0] < np.pi and abs(angles.wrap(mean[0] - np.pi)) < 0.05
    assert _same(D[:, 0], angles.wrap(Y[:, 0] - mean[0]))


# --- the Gaussian log-density ----------------------------------------------------------------
def test_one_gaussian_log_density():
    g = np.random.default_rng(2)
    maha, const = g.random(50) * 20, g.standard_normal(50)
    ref = -0.5 * (maha + const)
    assert _same(kernels.gauss_logpdf(maha, const), ref)
    assert _same([kernels.gauss_logpdf(a, c) for a, c in zip(maha, const)], ref)
    assert _same(kernels.gauss_logpdf.py_func(maha, const), ref)
    # the rows kernel (bootstrap PF, Model.loglik) and paper 002's kernels call it
    assert compiled.gauss_logpdf is kernels.gauss_logpdf and stcpf.gauss_logpdf is kernels.gauss_logpdf
    assert noise.gauss_logpdf is kernels.gauss_logpdf and likelihood.gauss_logpdf is kernels.gauss_logpdf
    assert pf_loop.gauss_loglik is kernels.gauss_loglik and model.kernels is kernels
    zh, z = g.standard_normal((7, 3)), g.standard_normal(3)
    out = np.empty(7)
    inv_var = np.array([1.0, 4.0, 0.25])
    kernels.gauss_loglik(zh, z, np.zeros(3, bool), True, np.zeros((0, 0)), inv_var, 1.5, out)
    d = z - zh
    assert _same(out, -0.5 * (((d[:, 0] * d[:, 0]) * inv_var[0] + (d[:, 1] * d[:, 1]) * inv_var[1])
                              + (d[:, 2] * d[:, 2]) * inv_var[2] + 1.5))


def test_stcpf_prior_loglik_is_the_gaussian_log_density():
    m = UNGM()
    flt = make_filter("stcpf", proposal="prior", n_particles=5)
    eng = flt.engine(m, [np.random.default_rng(0)])
    X = np.random.default_rng(3).standard_normal((1, 5, 1)) * 5
    z = np.array([[0.7]])
    meas = eng.measurement(3, None)
    R = m.measurement_cov(3)
    d = z[0, 0] - m.h(X, 3)[..., 0]
    expect = -0.5 * (d * d / R[0, 0] + np.log(R[0, 0]) + math.log(2 * math.pi))
    np.testing.assert_allclose(eng.loglik(z, X, 3, None, meas), expect, rtol=1e-14)
    np.testing.assert_allclose(m.loglik(z[0], X[0], 3), expect[0], rtol=1e-14)


# --- ESS, roughening, propagation noise -------------------------------------------------------
def test_pf_loop_calls_the_particle_kernels():
    for name in ("ess_rows", "perturb", "roughen", "weights", "moments"):
        assert getattr(pf_loop, name) is getattr(particles, name), name


def test_perturb_and_roughen_are_numpy_draws_bit_for_bit():
    g = np.random.default_rng(4)
    X = g.standard_normal((50, 3)) * [1.0, 10.0, 0.1]
    sd = np.array([0.5, 2.0, 0.01])
    got = X.copy()
    particles.perturb(got, sd, np.random.default_rng(9))
    assert _same(got, X + np.random.default_rng(9).standard_normal(X.shape) * sd)
    K = 0.3
    rough = particles.roughen(X.copy(), K, np.random.default_rng(9))
    shrink = 50 ** (-1.0 / 3)
    assert _same(rough, X + np.random.default_rng(9).standard_normal(X.shape) * (K * np.ptp(X, axis=0) * shrink))
    assert _same(particles.roughen.py_func(X.copy(), K, np.random.default_rng(9)), rough)
    # the bootstrap propagation draws the same noise (a diagonal Q): f(x) + sd e
    m = UNGM()
    Xs = g.standard_normal((2, 40, 1))
    Y = pf.propagate(m, Xs.copy(), 3, [np.random.default_rng(1), np.random.default_rng(2)])
    sdq = np.sqrt(np.diagonal(m.process_cov(3)))
    for j in range(2):
        expect = m.f(Xs[j], 3) + np.random.default_rng(j + 1).standard_normal((40, 1)) * sdq
        assert _same(Y[j], expect)


def test_one_ess():
    w = np.random.default_rng(5).random((4, 30))
    w /= w.sum(axis=1, keepdims=True)
    e = np.empty(4)
    particles.ess_rows(w, e)
    assert _same(particles.ess(w), e)
    np.testing.assert_allclose(e, 1.0 / (w * w).sum(axis=1), rtol=1e-14)
    one = np.empty(1)
    particles.ess_rows(w[2].reshape(1, -1), one)  # what the PF loop calls on its run
    assert one[0] == e[2]


# --- the fading factor ------------------------------------------------------------------------
@pytest.mark.parametrize("m_form", ["propagated", "printed"])
def test_fading_factor_kernel_equals_the_numpy_oracle(m_form):
    g = np.random.default_rng(6)
    for trial in range(40):
        nz, n = g.integers(1, 4), g.integers(2, 7)
        H, F = g.standard_normal((nz, n)), np.eye(n) + 0.1 * g.standard_normal((n, n))
        A, B = g.standard_normal((n, n)), g.standard_normal((nz, nz))
        P, Q, R = A @ A.T + np.eye(n), np.diag(g.random(n)), B @ B.T + np.eye(nz)
        e1, e2 = g.standard_normal(nz) * 3, g.standard_normal(nz) * 3
        st = compiled_util.Fading(0.95, 1.2, m_form == "propagated")
        V = np.empty((nz, nz))
        work = [np.empty((nz, n)) for _ in range(3)]
        lam1 = compiled_util.fading_factor(V, e1, True, H, F, P, Q, R, st, tuple(work))
        lam2 = compiled_util.fading_factor(V, e2, False, H, F, P, Q, R, st, tuple(work))
        V_ref = next_V(next_V(None, e1, 0.95), e2, 0.95)
        np.testing.assert_allclose(V, V_ref, rtol=1e-14)
        ref = oracle_fading(V_ref, H, F, P, Q, R, 1.2, m_form)
        assert lam2 == pytest.approx(float(ref), rel=1e-10, abs=0)
        assert lam1 >= 1.0


def test_stckf_calls_the_fading_kernel(monkeypatch):
    """The STCKF's lambdas are the kernel's: counted through a wrapper of it."""

    calls = []
    real = compiled_util.fading_factor

    def spy(*args):
        calls.append(real(*args))
        return calls[-1]

    monkeypatch.setattr(compiled_util, "fading_factor", spy)
    m = RandomWalkPosition(0.01 * np.eye(2), np.eye(2))
    z = np.cumsum(np.random.default_rng(7).standard_normal((30, 2)), axis=0) * 3
    res = stckf.STCKF().run(m, z, np.zeros(2), np.eye(2))
    assert len(calls) == 30 and list(res.info["lambda"]) == calls and max(calls) > 1.0


# --- the cubature step ------------------------------------------------------------------------
@pytest.mark.slow  # binds and compiles paper 002's kernels for the random-walk model (cached afterwards)
@pytest.mark.parametrize("stckf", [True, False])
def test_cubature_step_known_value(stckf):
    """On a linear-Gaussian model the particle's STCKF (CKF) is the exact Kalman update with the
    faded prior: x = [1, 2], P = 2 I, Q = 0.5 I, R = I, z = [5, -2]: e = [4, -4], tr N = 32 - 1 - 2.4,
    tr M = tr P = 4, lambda = 7.15; S = 2.5 lambda + 1, K = 2.5 lambda / S, P+ = 2.5 lambda / S."""

    m = RandomWalkPosition(0.5 * np.eye(2), np.eye(2))
    k = bind(m.kernels())
    x, z = np.array([1.0, 2.0]), np.array([5.0, -2.0])
    X, P, L = x.reshape(1, 1, 2).copy(), np.full((1, 1, 2, 2), 0.0), np.empty((1, 1, 2, 2))
    P[0, 0] = 2.0 * np.eye(2)
    V, logw, E = np.empty((1, 1, 2, 2)), np.zeros((1, 1)), np.zeros((1, 1, 2))
    lam, rep = np.empty((1, 1)), np.zeros((1, 1), np.int64)
    Q, R = m.Q, m.R
    pr = compiled_util.Proposal(stckf=stckf, fading=compiled_util.Fading(0.95, 1.2, True), scale_prior=True,
                                transition=False, have_L=False, have_V=False, logdet_Q=2 * math.log(0.5),
                                logdet_R=0.0, nzf=2)
    mask = np.zeros(2, bool)
    k.cubature_step(np.empty(0), np.empty(0), compiled_util.Particles(X, P, L, V, logw, lam, rep), z[None], None, E,
                    compiled_util.Noise(Q, np.linalg.inv(Q), R, np.linalg.inv(R), mask, mask), pr, 0, 1)
    g = 7.15 if stckf else 1.0
    S = 2.5 * g + 1.0
    post = x + (2.5 * g / S) * (z - x)
    assert lam[0, 0] == pytest.approx(g, rel=1e-14) and rep[0, 0] == 0
    np.testing.assert_allclose(X[0, 0], post, rtol=1e-14)
    np.testing.assert_allclose(P[0, 0], (2.5 * g / S) * np.eye(2), rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(L[0, 0], math.sqrt(2.5 * g / S) * np.eye(2), rtol=1e-14, atol=1e-15)
    if stckf:
        np.testing.assert_allclose(V[0, 0], np.outer(z - x, z - x), rtol=1e-14)
    # weight: log N(z; x+, R) + log N(x+; x, Q) (without 2 pi: it cancels) - log q(x+) (E = 0)
    ll = -0.5 * (np.sum((z - post) ** 2) + 2 * math.log(2 * math.pi))
    lp = -0.5 * (np.sum((post - x) ** 2) / 0.5 + 2 * math.log(0.5))
    lq = -0.5 * (2 * math.log(2.5 * g / S))
    assert logw[0, 0] == pytest.approx(ll + lp - lq, rel=1e-13)


@pytest.mark.slow  # two evaluations in fresh processes, one as plain Python
def test_plain_python_runs_the_stckf_and_the_stcpf():
    """NUMBA_DISABLE_JIT=1 runs the fading factor and the cubature step as their Python text,
    with the compiled numbers."""

    def run(plain, out):
        env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_JIT"}
        if plain:
            env["NUMBA_DISABLE_JIT"] = "1"
        cmd = [sys.executable, "-m", "replay.cli", "eval", "sim/auv-sonar", "--filters", "stckf,stcpf", "--runs", "1",
               "--dataset-param", "steps=12", "-p", "stcpf.n_particles=8", "-q", "-o", str(out)]
        res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
        assert res.returncode == 0, res.stderr
        return json.loads((out / "manifest.json").read_text())["results"]


    with tempfile.TemporaryDirectory() as tmp:
        plain, compiled = run(True, Path(tmp) / "p"), run(False, Path(tmp) / "c")
    for name in ("stckf", "stcpf"):
        for key in ("pos_rmse", "x_rmse", "final_err"):
            assert math.isfinite(compiled[name][key])
            assert plain[name][key] == pytest.approx(compiled[name][key], rel=1e-9, abs=0), (name, key)


@pytest.mark.slow  # binds and compiles paper 002's kernels for the sonar model (cached afterwards)
@pytest.mark.parametrize("stckf,transition", [(True, False), (False, False), (True, True)])
def test_cubature_step_python_text_equals_compiled(stckf, transition):
    """The cubature step run as its Python text (every kernel un-jitted: what NUMBA_DISABLE_JIT=1
    runs) gives the compiled numbers, on the sonar model's particles."""

    pb = make_task("sonar").build(make_frame(np.random.default_rng(1), steps=5), np.random.default_rng(2))
    m, g = pb.model, np.random.default_rng(8)
    M, N, n, nz = 2, 4, pb.model.nx, pb.model.nz
    X = pb.x0 + g.standard_normal((M, N, n)) @ np.linalg.cholesky(pb.P0).T
    P = np.broadcast_to(pb.P0, (M, N, n, n)).copy()
    Q, R = m.process_cov(1), m.measurement_cov(1)
    pf_, ph_ = (np.asarray(p, float) for p in m.kernel_params(1))
    pr = compiled_util.Proposal(stckf=stckf, fading=compiled_util.Fading(0.95, 1.2, True), scale_prior=True,
                                transition=transition, have_L=False, have_V=False,
                                logdet_Q=float(np.linalg.slogdet(Q)[1]), logdet_R=float(np.linalg.slogdet(R)[1]),
                                nzf=nz)
    xang, zang = np.zeros(n, bool), np.zeros(nz, bool)
    xang[list(m.x_angles)], zang[list(m.z_angles)] = True, True
    Z = np.ascontiguousarray(np.broadcast_to(pb.z[1], (M, nz)))
    E = g.standard_normal((M, N, n))
    k = bind(m.kernels())
    outs = []
    for step in (k.cubature_step, pure(k.cubature_step)):
        a = [X.copy(), P.copy(), np.empty((M, N, n, n)), np.empty((M, N, nz, nz)), np.zeros((M, N))]
        lam, rep = np.empty((M, N)), np.zeros((M, N), np.int64)
        noise = compiled_util.Noise(Q, np.linalg.inv(Q), R, np.linalg.inv(R), xang, zang)
        step(pf_, ph_, compiled_util.Particles(*a, lam, rep), Z, None, E, noise, pr, 0, M * N)
        outs.append(a[:3] + [a[4], lam, rep] + ([a[3]] if stckf else []))
    for c, p in zip(*outs):
        assert np.isfinite(c).all()
        np.testing.assert_allclose(p, c, rtol=1e-10, atol=0)
