"""Shared plumbing of the run loops (replay.filters.compiled.loops): the kernels' parameter stacks are kept
per model, and a model changed in any way (in place included) gets fresh ones."""
import numpy as np
import pytest

from replay.filters.compiled import JACOBIAN_ROWS, ROWS_KERNEL, loops
from replay.models.auv_sonar import AUVSonar


def test_parameter_stacks_follow_every_change_of_the_model():
    m = AUVSonar(dt=np.full(5, 1.0))
    Pf, Ph = loops.param_stacks(m, 5)
    assert Pf.shape == (5, 2) and np.array_equal(Pf[:, 0], np.ones(5)) and np.array_equal(Ph, np.zeros((5, 3)))
    assert loops.param_stacks(m, 5)[0] is Pf  # kept
    m.dt[2] = 0.5  # in place
    assert loops.param_stacks(m, 5)[0][2, 0] == 0.5
    m.yaw_rate = 0.3
    assert np.array_equal(loops.param_stacks(m, 5)[0][:, 1], np.full(5, 0.3))
    m.origin = np.array([1.0, 2.0, 3.0])
    assert np.array_equal(loops.param_stacks(m, 5)[1][4], [1.0, 2.0, 3.0])
    assert loops.param_stacks(m, 3)[0].shape == (3, 2)  # steps are part of the key
    assert loops.param_stacks(AUVSonar(dt=np.full(5, 1.0)), 5)[0][2, 0] == 1.0  # an equal new model: its own


def test_a_model_with_an_attribute_of_unknown_kind_is_never_kept():
    m = AUVSonar()
    m.extra = [1, 2]
    assert loops.fingerprint(m, 4) is None
    a, b = loops.param_stacks(m, 4), loops.param_stacks(m, 4)
    assert a[0] is not b[0] and np.array_equal(a[0], b[0])


@pytest.mark.slow  # compiles the rows forms of two models' kernels when numba's cache lacks them (~2 s)
def test_rows_forms_equal_the_models_array_methods_bit_for_bit():
    """The run loops' rows kernels (replay.filters.compiled.rows bound to the model) give the numbers of
    the model's own f, h, F, H on a stack of states; each is its own function (four addresses),
    typed by numba as the run loops' declared function types without a check."""
    import numba as nb

    from replay.models.random_walk import RandomWalkPosition

    @nb.njit
    def call(g, X, p, out):
        g(X, p, out)

    for m in (AUVSonar(), RandomWalkPosition(np.eye(3), np.eye(3))):
        fns = loops.row_kernels(m)
        assert len({fn.address for fn in fns}) == 4
        assert [nb.typeof(fn) for fn in fns] == [ROWS_KERNEL, ROWS_KERNEL, JACOBIAN_ROWS, JACOBIAN_ROWS]
        X = np.random.default_rng(0).normal(size=(40, m.nx)) * 3.0
        pf, ph = m.kernel_params(0)
        for fn, ref, p in zip(fns, (m.f(X, 0), m.h(X, 0), m.F(X, 0), m.H(X, 0)), (pf, ph, pf, ph)):
            out = np.full(ref.shape, np.nan)
            call(fn, X, p, out)
            assert np.array_equal(out, ref)


def test_many_short_jobs_compile_the_loop_once_their_work_adds_up(monkeypatch):
    """A job too short to pay for compiling a missing loop steps in Python; the jobs of one process
    (a tune's trials) add up, and the one that reaches the threshold compiles it."""

    class Loop:
        __name__, signatures, compiled = "loop", [], []

        def compile(self, sig):
            self.compiled.append(sig)

        def disable_compile(self):
            pass

    monkeypatch.setattr(loops.numba_internals, "jit_disabled", lambda: False)
    monkeypatch.setattr(loops.numba_internals, "from_cache", lambda loop, sig: False)
    loop, sig = Loop(), object()
    assert [loops.loop_ready(loop, sig, False, 40.0, 100.0) for _ in range(2)] == [False, False]
    assert loop.compiled == []
    assert loops.loop_ready(loop, sig, False, 40.0, 100.0)  # 120 >= 100: compiled now
    assert loop.compiled == [sig] and loops.loop_ready(loop, sig, False)
    other = Loop()
    other.compiled = []
    assert not loops.loop_ready(other, sig, False, 99.0, 100.0)  # its own count
