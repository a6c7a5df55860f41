"""Paper 003's formation model under a filter's noise settings (q_scale, r_scale, Q, R): the draws
and the glint likelihood follow them, or the setting is refused in one line."""
import copy

import numpy as np
import pytest

from replay.filters import noise_params
from replay.models.formation import Formation
from replay.models.noise import Glint
from replay.util.errors import ReplayError


def model():
    g = Glint(np.diag([25.0, 1e-4]), np.diag([25.0, 4e-4]), eps=0.75)
    return Formation(np.zeros((3, 2)), 0.0, 1.0, 0.5 * np.eye(2), g)


def changed(m, **settings):
    m = copy.copy(m)
    for k, v in settings.items():
        setattr(m, k, v)
    m.refresh_noise()
    return m


def test_q_scale_scales_the_acceleration_draws():
    m = model()
    new = changed(m, Q=m.Q * 4.0)
    assert np.allclose(new.Qa, 4.0 * m.Qa) and np.allclose(new._La, 2.0 * m._La)
    x = np.zeros((20000, 4))
    d = new.sample_f(x, 0, np.random.default_rng(0)) - m.f(x, 0)
    assert np.allclose(np.cov(d.T), new.Q, atol=0.05)  # the draws have the scaled covariance
    assert np.array_equal(m._La, np.linalg.cholesky(0.5 * np.eye(2)))  # the task's model is untouched


def test_r_scale_scales_the_glint_likelihood():
    m = model()
    new = changed(m, R=m.R * 3.0)
    assert np.allclose(new.noise.cov, 3.0 * m.noise.cov)
    e = np.array([[4.0, 0.01], [-9.0, 0.03]])
    want = Glint(m.noise.P1 * 3.0, m.noise.P2 * 3.0, 0.75).logpdf(e)
    assert np.allclose(new.noise.logpdf(e), want)


@pytest.mark.parametrize("what, value, words", [
    ("Q", np.eye(4), "Q must be G Q_a"),
    ("R", np.diag([25.0, 1.0]), "R must be a multiple"),
])
def test_other_noise_is_refused(what, value, words):
    with pytest.raises(ReplayError, match=words):
        changed(model(), **{what: value})


def test_filter_noise_settings_reach_the_model():
    from replay.filters.pf import ParticleFilter

    m = model()
    new, _ = noise_params.apply(ParticleFilter(q_scale=2.0, r_scale=0.5), m, np.eye(4)[None])
    assert np.allclose(new.Qa, 2 * m.Qa) and np.allclose(new.noise.cov, 0.5 * m.noise.cov)
    assert np.allclose(m.Qa, 0.5 * np.eye(2))
