"""Kalman filter and extended Kalman filter.

Equations (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, 2001, ch. 5 and 10):

    predict   x = f(x),  P = F P F' + Q                 F = df/dx at the prior
    update    y = z - h(x)  (angle components wrapped)
              S = H P H' + R,  K = P H' S^-1
              x = x + K y  (state angles wrapped),  P = (I - K H) P (I - K H)' + K R K'

The Joseph form keeps P symmetric positive semi-definite. ``KalmanFilter`` is
the EKF applied to a linear model (its Jacobians are the model matrices), so
the two cannot drift apart.
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import residual, wrap_components
from replay.util.linalg import gain
from replay.model import remap_indices

from .base import Filter


def kalman_gain_update(x, P, y, H, R, x_angles=()):
    """Update (x, P) with innovation ``y``, Jacobian ``H`` and noise ``R``; Joseph form."""
    PHt = P @ H.T
    S = H @ PHt + R
    K = gain(S, PHt)
    x = wrap_components(x + K @ y, x_angles)
    I_KH = np.eye(len(x)) - K @ H
    P = I_KH @ P @ I_KH.T + K @ R @ K.T
    return x, 0.5 * (P + P.T)


class EKF(Filter):
    """Extended Kalman filter (first order), with model or numerical Jacobians."""

    name = "ekf"

    def predict(self, state, k):
        m = state.model
        F = m.F(state.x, k)
        state.x = wrap_components(m.f(state.x, k), m.x_angles)
        state.P = F @ state.P @ F.T + m.process_cov(k)

    def update(self, state, z, k, mask):
        m = state.model
        H = m.H(state.x, k)
        zh = m.h(state.x, k)
        R = m.measurement_cov(k)
        angles = m.z_angles
        if mask is not None:
            H, zh, z, R = H[mask], zh[mask], z[mask], R[np.ix_(mask, mask)]
            angles = remap_indices(angles, mask)
        y = residual(z, zh, angles)
        state.x, state.P = kalman_gain_update(state.x, state.P, y, H, R, m.x_angles)


class KalmanFilter(EKF):
    """The Kalman filter: exact for :class:`replay.model.LinearGaussian` models."""

    name = "kf"
