"""Issue 17's speed-ups of paper 002 keep the numbers: the compiled PSO passes, draws and angle wraps
equal their numpy readings bit for bit (the numpy PSO is the test oracle ``tests/oracle_p002.py``)."""
from __future__ import annotations

import numba as nb
import numpy as np
import pytest

from replay.filters.p002 import compiled_util, gwo, pso, stack
from replay.util.angles import residual, wrap

from oracle_p002 import pso_optimize


def special_angles(shape, seed=0):
    """Normal values with +-pi, +-3, the wrap's edges, huge values and NaN planted in them."""
    X = np.random.default_rng(seed).normal(0.0, 4.0, shape)
    flat = X.reshape(-1, shape[-1])
    for r, v in enumerate([np.pi, -np.pi, 3.0, -3.0, 2.9999999, 3.0000001, 7 * np.pi, -1e6, np.nan, 0.0, -0.0]):
        flat[r, -1] = v
        flat[-1 - r, -2] = v
    return X


@pytest.mark.parametrize("angles", [(4, 5), (5,), (0, 3), (1, 2, 4)])
def test_wrap_inplace_is_the_numpy_wrap_bit_for_bit(angles):
    """The compiled wrap of a contiguous stack (rows with small angles skipped) and the numpy path of
    a strided one give :func:`replay.util.angles.wrap` of the angle columns, bit for bit."""
    X = special_angles((5, 13, 6))
    ref = X.copy()
    ref[..., list(angles)] = wrap(ref[..., list(angles)])
    got = stack.wrap_inplace(X.copy(), angles)
    assert np.array_equal(got, ref, equal_nan=True)
    strided = X.copy()[:, ::2]
    assert not strided.flags.c_contiguous
    assert np.array_equal(stack.wrap_inplace(strided, angles), ref[:, ::2], equal_nan=True)
    assert not np.array_equal(got, X, equal_nan=True)  # something was wrapped
    a, b = special_angles((4, 7, 6), 1), special_angles((4, 7, 6), 2)
    assert np.array_equal(stack.fast_residual(a, b, angles), residual(a, b, angles), equal_nan=True)


def test_scaled_draws_are_the_uniforms_times_the_scales():
    shape = (5, 2, 7, 3)
    scales = np.random.default_rng(9).uniform(0.5, 2.0, (5, 2))
    ref = gwo.draws([np.random.default_rng(1), np.random.default_rng(2)], shape) * scales[None, :, :, None, None]
    got = gwo.scaled_draws([np.random.default_rng(1), np.random.default_rng(2)], shape, scales)
    assert got.shape == (2,) + shape and np.array_equal(got, ref)


def fitness_with_ties(X):
    """A bowl around (1, -2, 0.5, ...) rounded to 1/8: many equal values (np.argmin's first index counts)."""
    target = np.array([1.0, -2.0, 0.5, 3.0])[: X.shape[-1]]
    return np.floor(8 * np.sum((X - target) ** 2 * np.array([1.0, 2.0, 0.5, 1.5])[: X.shape[-1]], axis=-1)) / 8


@pytest.mark.parametrize("case", ["plain", "bounded", "movable", "single"])
def test_pso_equals_its_numpy_reading_bit_for_bit(case):
    """pso.optimize (compiled passes) and the numpy PSO of the oracle: same positions, fitness and bests."""
    X = np.random.default_rng(4).normal(0.0, 3.0, (3, 40, 4))
    lo, hi = np.array([-2.0, -5.0, -1.0, 0.0]), np.array([2.0, 5.0, 1.0, 4.0])
    kw = {"project": (lambda Y: np.clip(Y, lo, hi))} if case == "bounded" else {}
    if case == "movable":
        kw["movable"] = np.array([[True, False, True, True], [True, True, True, True], [False, True, False, True]])
    if case == "single":
        a = pso.optimize(X[0], fitness_with_ties, np.random.default_rng(7), 15)
        b = pso_optimize(X[0], fitness_with_ties, np.random.default_rng(7), 15)
    else:
        rngs = lambda: [np.random.default_rng(10 + j) for j in range(3)]  # noqa: E731
        a = pso.optimize(X, fitness_with_ties, rngs(), 15, c1=(2.5, 0.5), **kw)
        b = pso_optimize(X, fitness_with_ties, rngs(), 15, c1=(2.5, 0.5), **kw)
    for u, v in zip(a, b):
        assert u.shape == v.shape and np.array_equal(u, v)
    assert np.all(a[2][..., -1] < a[2][..., 0])  # the swarm improved
    if case == "movable":
        assert np.array_equal(a[0][0, :, 1], X[0, :, 1]) and np.array_equal(a[0][2, :, 2], X[2, :, 2])


def test_pso_refuses_a_fitness_that_is_not_finite():
    """A NaN fitness at the start is the swarm's best (np.argmin's first NaN): a numerical divergence."""
    X = np.zeros((10, 2))
    X[3, 0] = 1.0

    def fit(Y):
        return np.where(Y[..., 0] > 0, np.nan, 1.0 + Y[..., 1] ** 2)

    with pytest.raises(FloatingPointError, match="PSO fitness not finite"):
        pso.optimize(X, fit, np.random.default_rng(0), 5)
    assert np.isnan(pso_optimize(X, fit, np.random.default_rng(0), 5)[2]).all()


@nb.njit
def numba_sum_of_product(A, B):  # what the STCKF fading factor computed before (a temporary array)
    return np.sum(A * B)


@pytest.mark.slow
def test_fading_factor_trace_sum_is_the_former_array_sum_bit_for_bit():
    """``frobenius`` (no temporary) sums in numba's np.sum order: the fading factor's bits are unchanged."""
    frob = compiled_util.frobenius  # the fading factor's (compiled_util.fading_factor)
    g = np.random.default_rng(3)
    for shape in ((3, 6), (2, 6), (1, 3), (6, 6)):
        A, B = g.normal(size=shape) * 10.0 ** g.integers(-8, 8, shape), g.normal(size=shape)
        assert frob(A, B) == numba_sum_of_product(A, B)

