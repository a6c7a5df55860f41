import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from replay.filters import Filter, Param
from replay.model import remap_indices
from replay.util.angles import residual, weighted_mean


class FilterPyUKF(Filter):
    """FilterPy's UnscentedKalmanFilter, one per Monte Carlo run, with the model's angles wrapped and averaged."""
    name = "filterpy-ukf"
    PARAMS = (Param("alpha", float, 0.5, "spread of the sigma points", low=0.0, low_open=True),
              Param("beta", float, 2.0, "prior knowledge of the distribution (2: Gaussian)", low=0.0))
    estimate = staticmethod(lambda state: (state.ukf.x, state.ukf.P))  # the posterior mean and covariance

    def start(self, state, x0, P0):
        m = state.model
        dx = lambda a, b: residual(a, b, m.x_angles)  # noqa: E731
        pts = MerweScaledSigmaPoints(m.nx, self.alpha, self.beta, 0.0, subtract=dx)
        state.ukf = UnscentedKalmanFilter(m.nx, m.nz, 1.0, m.h, lambda x, dt, k: m.f(x, k), pts, residual_x=dx,
                                          x_mean_fn=lambda s, w: weighted_mean(s, w, m.x_angles))
        state.ukf.x, state.ukf.P = np.array(x0, float), np.array(P0, float)

    def predict(self, state, k):
        state.ukf.Q = state.model.process_cov(k)
        state.ukf.predict(k=k)

    def update(self, state, z, k, mask):  # mask: the measured components when z is partly missing
        m, ukf = state.model, state.ukf
        keep = np.ones(m.nz, bool) if mask is None else np.asarray(mask, bool)
        angles = remap_indices(m.z_angles, keep)  # the angles among the measured components
        ukf.residual_z = lambda a, b: residual(a, b, angles)
        ukf.z_mean = lambda s, w: weighted_mean(s, w, angles)
        ukf.update(z[keep], R=m.measurement_cov(k)[np.ix_(keep, keep)], hx=lambda x, k: m.h(x, k)[keep], k=k)
        state.innovation = (ukf.y, ukf.S)  # replay records the NIS of this step
