"""``example-filter``: an iterated extended Kalman filter, written over the Monte Carlo run axis.

The measurement update is Gauss-Newton on the measurement residual (Bell and Cathey 1993):
from x_0 = the predicted mean, repeat

    H_i = dh/dx (x_i),  S_i = H_i P H_iᵀ + R,  K_i = P H_iᵀ S_i⁻¹
    x_{i+1} = x_pred + K_i (z - h(x_i) - H_i (x_pred - x_i))

``iterations`` times, or until the state moves less than ``tolerance``; then the
covariance update (Joseph form) with the last gain. One iteration is the EKF.

It shows the filter protocol of replay (``filters/base.py``): declared parameters
(``PARAMS``), an ``engine(model, rngs)`` stepping M runs at once, declared angles
(residuals of ``model.x_angles`` / ``model.z_angles`` wrapped), missing measurement
components (``finite``) and the normalised innovation squared. The engine steps each
run on its own slice, so a run's numbers do not depend on the runs of its batch.
"""
from __future__ import annotations

import numpy as np

from replay.filters import Filter
from replay.util.angles import residual, wrap_components
from replay.util.params import Param


class IteratedEKF(Filter):
    """Iterated extended Kalman filter (Gauss-Newton measurement update); the example plugin's filter."""

    name = "example-filter"
    PARAMS = (
        Param("iterations", int, 5, "Gauss-Newton iterations of the measurement update (1 = the EKF)",
              low=1, high=100),
        Param("tolerance", float, 1e-6, "stop iterating when the state moves less than this (max-norm)",
              low=0.0),
    )

    def engine(self, model, rngs):
        return IteratedEngine(self, model, len(rngs))


class IteratedEngine:
    """M runs: ``start``, ``step``, ``keep``, ``finish`` (the engine protocol of ``filters/base.py``)."""

    def __init__(self, flt: IteratedEKF, model, runs: int):
        self.flt, self.model, self.runs = flt, model, runs
        self.iterations = np.zeros(runs, int)  # Gauss-Newton iterations done, per run
        self.ids = np.arange(runs)

    def start(self, X0, P0):
        self.x, self.P = X0.copy(), P0.copy()

    def keep(self, ok):
        self.x, self.P, self.ids = self.x[ok], self.P[ok], self.ids[ok]

    def step(self, k, Z, finite):
        m = self.model
        Q, R = m.process_cov(k), m.measurement_cov(k)
        xp = m.f(self.x, k)  # all active runs at once: f takes (..., nx)
        nis, dof = np.full(len(xp), np.nan), np.zeros(len(xp), int)
        for j in range(len(xp)):  # the linear algebra run by run: each on its own slice
            F = m.F(self.x[j], k)
            P = F @ self.P[j] @ F.T + Q
            use = finite[j]
            x = xp[j]
            if use.any():
                x, P, nis[j], n = self.update(x, P, Z[j], use, R, k)
                dof[j] = use.sum()
                self.iterations[self.ids[j]] += n
            self.x[j], self.P[j] = x, P
        return self.x.copy(), self.P.copy(), nis, dof

    def update(self, xp, P, z, use, R, k):
        """The iterated update of one run: (x, P, NIS of the first iteration, iterations)."""
        m, flt = self.model, self.flt
        cols = np.flatnonzero(use)
        z_angles = [i for i, c in enumerate(cols) if c in m.z_angles]  # angles among the used components
        z, R = z[cols], R[np.ix_(cols, cols)]
        x, nis = xp, np.nan
        for i in range(flt.iterations):
            H = m.H(x, k)[cols]
            r = residual(z, m.h(x, k)[cols], z_angles) - H @ residual(xp, x, m.x_angles)
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T  # P H' S^-1 (S and P symmetric)
            if i == 0:
                nis = float(r @ np.linalg.solve(S, r))
            new = wrap_components(xp + K @ r, m.x_angles)
            moved = np.max(np.abs(residual(new, x, m.x_angles)))
            x = new
            if moved < flt.tolerance:
                break
        A = np.eye(len(x)) - K @ H
        P = A @ P @ A.T + K @ R @ K.T  # Joseph form: symmetric, positive semi-definite
        return x, 0.5 * (P + P.T), nis, i + 1

    def finish(self, m, info):
        info["iterations"] = int(self.iterations[m])
