"""The models' array methods, derived from their one-state numba kernels (replay.models.kernel_model).

Checked against hand-computed values and against the numpy expressions the models
had before their kernels became the one source (kept here as the oracle).
"""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from replay.models.auv_sonar import AUVSonar
from replay.models.random_walk import RandomWalkPosition
from replay.models.ungm import UNGM


# --- the numpy expressions of the models before (independent of the kernels) -----------------
def sonar_f(m, x, k):
    T = m._dt(k)
    v, th, ps = x[..., 3], x[..., 4], x[..., 5]
    vc = v * np.cos(th) * T
    y = x.copy()
    y[..., 0] += vc * np.cos(ps)
    y[..., 1] += vc * np.sin(ps)
    y[..., 2] -= v * np.sin(th) * T
    y[..., 5] += m.yaw_rate * T
    return y


def sonar_F(m, x, k):
    T = m._dt(k)
    v, th, ps = x[..., 3], x[..., 4], x[..., 5]
    c, s, cp, sp = np.cos(th), np.sin(th), np.cos(ps), np.sin(ps)
    J = np.zeros(np.shape(x)[:-1] + (6, 6))
    J[..., range(6), range(6)] = 1.0
    J[..., 0, 3], J[..., 0, 4], J[..., 0, 5] = c * cp * T, -v * s * cp * T, -v * c * sp * T
    J[..., 1, 3], J[..., 1, 4], J[..., 1, 5] = c * sp * T, -v * s * sp * T, v * c * cp * T
    J[..., 2, 3], J[..., 2, 4] = -s * T, -v * c * T
    return J


def sonar_h(m, x, k):
    d = x[..., :3] - m.origin
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    rho = np.sqrt(dx * dx + dy * dy)
    return np.stack([np.sqrt(dx * dx + dy * dy + dz * dz), np.arctan2(dz, rho), np.arctan2(dy, dx)], -1)


def sonar_H(m, x, k):
    d = x[..., :3] - m.origin
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    rho2 = dx * dx + dy * dy
    r2 = rho2 + dz * dz
    J = np.zeros(np.shape(x)[:-1] + (3, 6))
    bad = (r2 == 0.0) | (rho2 == 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r, rho = np.sqrt(r2), np.sqrt(rho2)
        J[..., 0, 0], J[..., 0, 1], J[..., 0, 2] = dx / r, dy / r, dz / r
        J[..., 1, 0], J[..., 1, 1], J[..., 1, 2] = -dx * dz / (r2 * rho), -dy * dz / (r2 * rho), rho / r2
        J[..., 2, 0], J[..., 2, 1] = -dy / rho2, dx / rho2
    J[bad] = 0.0
    return J


def ungm_f(m, x, k):
    return 0.5 * x + m.growth * x / (1.0 + x * x) + 8.0 * np.cos(1.2 * (k + m.k0))


def ungm_F(m, x, k):
    x = x[..., :1, None]
    return 0.5 + m.growth * (1.0 - x * x) / (1.0 + x * x) ** 2


REFERENCE = {
    "auv-sonar": (lambda: AUVSonar(dt=0.7, yaw_rate=0.3, origin=(5.0, -3.0, 1.0)),
                  (sonar_f, sonar_h, sonar_F, sonar_H)),
    "ungm": (lambda: UNGM(Q=2.0, R=3.0, growth=25.0),
             (ungm_f, lambda m, x, k: x * x / 20.0, ungm_F, lambda m, x, k: x[..., :1, None] / 10.0)),
    "random-walk": (lambda: RandomWalkPosition(np.eye(3), 2 * np.eye(3)),
                    (lambda m, x, k: x, lambda m, x, k: x,
                     lambda m, x, k: np.broadcast_to(np.eye(3), x.shape + (3,)),
                     lambda m, x, k: np.broadcast_to(np.eye(3), x.shape + (3,)))),
}
SHAPES = [(), (1,), (13,), (4, 7), (3, 5, 9)]  # leading axes: one state, stacks (M, nx), (M, N, nx), ...


def states(m, lead, seed=0):
    mean = np.array([40, -20, -30, 8, 0.5, 2.5])[:m.nx]
    sd = np.array([30, 30, 30, 2, 0.5, 2.0])[:m.nx]
    return np.random.default_rng(seed).normal(mean, sd, lead + (m.nx,))


@pytest.mark.parametrize("lead", SHAPES, ids=str)
@pytest.mark.parametrize("name", REFERENCE)
def test_array_methods_equal_the_numpy_expressions(name, lead):
    make, ref = REFERENCE[name]
    m = make()
    x = states(m, lead)
    x_before = x.copy()
    for k in (0, 3):
        for meth, expected in zip("fhFH", ref):
            got = getattr(m, meth)(x, k)
            want = expected(m, x, k)
            shape = {"f": (m.nx,), "h": (m.nz,), "F": (m.nx, m.nx), "H": (m.nz, m.nx)}[meth]
            assert got.shape == lead + shape and got.dtype == np.float64, meth
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15, err_msg=f"{name}.{meth}")
    np.testing.assert_array_equal(x, x_before)  # the input is not written


@pytest.mark.parametrize("name", REFERENCE)
def test_one_state_equals_the_same_state_in_a_stack(name):
    """One state goes through the kernel itself, a stack through its gufunc: the same numbers
    (to rounding: numba may vectorise the stack's loop, with other sin/cos roundings)."""
    m = REFERENCE[name][0]()
    X = states(m, (3, 4), seed=1)
    for meth in "fhFH":
        stack = getattr(m, meth)(X, 2)
        for i in range(3):
            for j in range(4):
                np.testing.assert_allclose(getattr(m, meth)(X[i, j], 2), stack[i, j], rtol=1e-14, atol=1e-13)


def test_sonar_hand_computed():
    m = AUVSonar(dt=0.5, yaw_rate=0.2, origin=(5.0, -3.0, 1.0))
    x = np.array([8.0, 1.0, 13.0, 2.0, np.pi / 3, np.pi / 2])  # offset (3, 4, 12) from the sonar
    np.testing.assert_allclose(m.h(x, 0), [13.0, np.arctan2(12.0, 5.0), np.arctan2(4.0, 3.0)], rtol=1e-15)
    H = np.zeros((3, 6))
    H[0, :3] = [3 / 13, 4 / 13, 12 / 13]
    H[1, :3] = [-36 / 845, -48 / 845, 5 / 169]
    H[2, :2] = [-4 / 25, 3 / 25]
    np.testing.assert_allclose(m.H(x, 0), H, rtol=1e-14, atol=1e-17)
    # v = 2, pitch 60 deg, yaw 90 deg, T = 0.5: y += v cos(pitch) T = 0.5, z -= v sin(pitch) T
    np.testing.assert_allclose(m.f(x, 0), [8.0, 1.5, 13.0 - np.sqrt(3) / 2, 2.0, np.pi / 3, np.pi / 2 + 0.1],
                               rtol=1e-15, atol=1e-15)
    F = m.F(x, 0)
    np.testing.assert_allclose(F[:3, 3:], [[0.0, 0.0, -0.5], [0.25, -np.sqrt(3) / 2, 0.0], [-np.sqrt(3) / 4, -0.5, 0.0]],
                               rtol=1e-15, atol=1e-16)
    np.testing.assert_array_equal(F[:3, :3], np.eye(3))
    np.testing.assert_array_equal(F[3:], np.eye(6)[3:])


def test_sonar_steps_of_their_own_length():
    m = AUVSonar(dt=[0.5, 1.0, 2.0], yaw_rate=0.1)
    x = np.array([0.0, 0.0, 0.0, 3.0, 0.0, 0.0])
    np.testing.assert_allclose(m.f(x, 2), [6.0, 0.0, 0.0, 3.0, 0.0, 0.2])
    np.testing.assert_allclose(m.f(np.stack([x, x]), 0)[:, 0], [1.5, 1.5])


def test_sonar_jacobian_is_zero_at_the_sonar_and_above_it():
    m = AUVSonar(origin=(5.0, -3.0, 1.0))
    at = np.array([5.0, -3.0, 1.0, 1.0, 0.0, 0.0])
    above = np.array([5.0, -3.0, 9.0, 1.0, 0.0, 0.0])
    assert not m.H(at, 0).any() and not m.H(above, 0).any()
    np.testing.assert_array_equal(m.h(at, 0), [0.0, 0.0, 0.0])
    X = np.stack([at, above, [8.0, 1.0, 13.0, 0.0, 0.0, 0.0]])[None].repeat(2, axis=0)  # (2, 3, 6)
    J = m.H(X, 0)
    assert not J[:, :2].any() and J[:, 2].any()
    np.testing.assert_allclose(J, sonar_H(m, X, 0), rtol=1e-12)


def test_ungm_hand_computed():
    m = UNGM()  # g = 2.5, k0 = 1: step 0 is model time 1
    assert m.f(np.array([1.0]), 0)[0] == pytest.approx(0.5 + 2.5 / 2 + 8 * np.cos(1.2), rel=1e-15)
    assert UNGM(growth=25.0).f(np.array([1.0]), 0)[0] == pytest.approx(13.0 + 8 * np.cos(1.2), rel=1e-15)
    assert m.F(np.array([1.0]), 0)[0, 0] == 0.5  # the growth term is flat at x = 1
    assert m.F(np.array([0.0]), 0)[0, 0] == 3.0
    np.testing.assert_array_equal(m.h(np.array([[2.0], [-4.0]]), 0), [[0.2], [0.8]])
    np.testing.assert_array_equal(m.H(np.array([[2.0], [-4.0]]), 0), [[[0.2]], [[-0.4]]])


def test_random_walk_is_the_identity_and_returns_its_own_array():
    m = RandomWalkPosition(np.eye(3), np.eye(3))
    x = np.arange(6.0).reshape(2, 3)
    y = m.f(x, 0)
    np.testing.assert_array_equal(y, x)
    assert not np.shares_memory(y, x)
    np.testing.assert_array_equal(m.H(x[0], 0), np.eye(3))
    assert m.vector_jacobians and m.F(x, 0).shape == (2, 3, 3)


def test_states_of_the_wrong_size_are_refused():
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        AUVSonar().f(np.zeros((4, 3)), 0)
    with pytest.raises(ValueError):
        UNGM().h(np.float64(1.0), 0)


def test_inputs_are_taken_as_float_in_any_layout():
    m = AUVSonar(origin=(1.0, 2.0, 3.0))
    X = np.asfortranarray(states(m, (5, 4)))[:, ::2]  # neither C- nor F-contiguous
    np.testing.assert_allclose(m.h(X, 0), sonar_h(m, X, 0), rtol=1e-12)
    np.testing.assert_allclose(m.F(X[0, 0], 0), sonar_F(m, X[0, 0], 0), rtol=1e-12)
    np.testing.assert_array_equal(m.f([0, 0, 0, 1, 0, 0], 0), m.f(np.array([0.0, 0, 0, 1, 0, 0]), 0))


def test_models_pickle():
    m = pickle.loads(pickle.dumps(AUVSonar(dt=0.7)))
    np.testing.assert_array_equal(m.f(np.ones(6), 0), AUVSonar(dt=0.7).f(np.ones(6), 0))
