"""Shared plumbing of the run loops (replay.filters.loops): the kernels' parameter stacks are kept
per model, and a model changed in any way (in place included) gets fresh ones."""
import numpy as np

from replay.filters import loops
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
