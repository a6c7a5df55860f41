import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from replay.filters import Filter, Param
from replay.util.angles import residual, weighted_mean


class FilterPyUKF(Filter):
    """FilterPy's UnscentedKalmanFilter, one per Monte Carlo run, with the model's angles wrapped and averaged."""
    name = "filterpy-ukf"
    PARAMS = (Param("alpha", float, 0.5, "spread of the sigma points", low=0.0, low_open=True),
              Param("beta", float, 2.0, "prior knowledge of the distribution (2: Gaussian)", low=0.0))
    estimate = staticmethod(lambda state: (state.ukf.x, state.ukf.P))  # the posterior mean and covariance

    def start(self, state, x0, P0):
        m = state.model
        dx, dz = (lambda a, b: residual(a, b, m.x_angles)), (lambda a, b: residual(a, b, m.z_angles))
        pts = MerweScaledSigmaPoints(m.nx, self.alpha, self.beta, 0.0, subtract=dx)
        state.ukf = UnscentedKalmanFilter(m.nx, m.nz, 1.0, m.h, lambda x, dt, k: m.f(x, k), pts, residual_x=dx,
                                          residual_z=dz, x_mean_fn=lambda s, w: weighted_mean(s, w, m.x_angles),
                                          z_mean_fn=lambda s, w: weighted_mean(s, w, m.z_angles))
        state.ukf.x, state.ukf.P = np.array(x0, float), np.array(P0, float)

    def predict(self, state, k):
        state.ukf.Q = state.model.process_cov(k)
        state.ukf.predict(k=k)

    def update(self, state, z, k, mask):  # FilterPy's z has a fixed size: a partly missing z is skipped
        if mask is None:
            state.ukf.update(z, R=state.model.measurement_cov(k), k=k)
