"""``gtsam-lag``: GTSAM's incremental fixed-lag smoother over the factors of ``gtsam-batch``.

Causal with a delay: the estimate of the state at time t uses every measurement up to t + lag
(seconds) and none after. The factors are those of :mod:`replay.filters.factor_graph` (prior,
process, measurement: the filters' own model, inputs and noise), added step by step to a
:class:`gtsam.IncrementalFixedLagSmoother` (iSAM2 over a window of ``lag`` seconds; the states that
leave it are marginalised into a prior on the window). A state is read (its mean and its
marginal covariance) after the last step within ``lag`` of it, just before the next step would
marginalise it; the states of the last ``lag`` seconds at the end.

Each factor is linearised once, when it enters the window, at the smoother's estimate of that
moment (the new state at its prediction ``f(x)`` from the latest estimate of the one before, as an
EKF linearises) and kept as a :class:`gtsam.LinearContainerFactor`: the window's solution is
exact for those linearisations, but they are not revisited as ``gtsam-batch``'s are (the fusion
task's only nonlinearity is the heading's rotation of the body velocity). The time of a step is
the model's: its steps' ``dt`` summed; a model without ``dt`` (no time axis) is refused.
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import ReplayError
from replay.util.params import Param

from .case import Case
from .factor_graph import Graph, Smoother, gtsam_module, wrap_rows


class GtsamLag(Smoother):
    """Smoother, causal with a delay: GTSAM's fixed-lag smoother over lag seconds (extra [smooth])."""

    name = "gtsam-lag"
    CASE = Case(params={"lag": 0.5})
    PARAMS = (
        Param(
            "lag",
            float,
            1.0,
            "the smoother's lag: the estimate at t uses the measurements up to t + lag",
            unit="s",
            low=0.0,
        ),
    )

    def solve(self, model, z, x0, P0):
        gtsam = gtsam_module(self.name)
        dt = getattr(model, "dt", None)
        if dt is None:
            raise ReplayError(
                f"filter {self.name!r}: the task's model has no time step (dt): a lag in seconds needs one; "
                "use gtsam-batch"
            )
        graph = Graph(model, z, x0, P0)
        n, nx = graph.n, graph.nx
        steps = np.broadcast_to(np.asarray(dt, float), (n,)) if np.ndim(dt) == 0 else np.asarray(dt, float)[:n]
        t = np.concatenate([[0.0], np.cumsum(steps)])  # key k + 1 is step k; key 0 the prior (a constant dt too)
        params = gtsam.ISAM2Params()
        params.setFactorization("QR")  # the zero-dt steps make stiff process factors: QR, not Cholesky
        exact = gtsam.ISAM2GaussNewtonParams()
        exact.setWildfireThreshold(0.0)  # every state's update back-substituted, however small
        params.setOptimizationParams(exact)
        smoother = gtsam.IncrementalFixedLagSmoother(self.lag, params)
        measured = graph.by_step()
        X, P = np.full((n, nx), np.nan), np.full((n, nx, nx), np.nan)
        unit = gtsam.noiseModel.Unit.Create(nx)
        first = gtsam.GaussianFactorGraph()
        first.add(gtsam.JacobianFactor(0, graph.W0, np.zeros(nx), unit))
        prev = np.asarray(x0, float)
        self._add(gtsam, smoother, first, {0: prev}, {0: t[0]})
        read = 1  # the next key to read
        for k in range(n):
            x = np.asarray(model.f(prev, k), float)  # the new state's linearisation point: the prediction
            lin = gtsam.GaussianFactorGraph()
            W = graph.WQ[k]
            lin.add(gtsam.JacobianFactor(k, -W @ np.asarray(model.F(prev, k)), k + 1, W, np.zeros(nx), unit))
            if k in measured:
                cols, Wr = measured[k]
                e = np.asarray(model.h(x, k), float)[cols] - graph.z[k, cols]
                e = wrap_rows(e, [i for i, c in enumerate(cols) if c in graph.z_angles])
                H = np.asarray(model.H(x, k), float)[cols]
                lin.add(gtsam.JacobianFactor(k + 1, Wr @ H, -(Wr @ e), gtsam.noiseModel.Unit.Create(len(cols))))
            self._add(gtsam, smoother, lin, {k: prev, k + 1: x}, {k + 1: t[k + 1]}, new=(k + 1,))
            prev = smoother.calculateEstimateVector(k + 1)
            horizon = t[k + 2] - self.lag if k + 2 <= n else np.inf  # the next step marginalises before it
            while read <= k + 1 and t[read] < horizon:
                X[read - 1] = smoother.calculateEstimateVector(read)
                P[read - 1] = smoother.marginalCovariance(read)
                read += 1
        return wrap_rows(X, graph.x_angles), P, {"lag_s": self.lag}

    @staticmethod
    def _add(gtsam, smoother, lin, points, stamps, new=(0,)):
        """``lin`` (linearised at ``points``: key -> state) into the smoother as fixed linear factors,
        the keys ``new`` entering it at their ``stamps``."""
        at = gtsam.Values()
        for key, x in points.items():
            at.insert(key, np.asarray(x, float))
        graph = gtsam.NonlinearFactorGraph()
        for i in range(lin.size()):
            graph.add(gtsam.LinearContainerFactor(lin.at(i), at))
        values = gtsam.Values()
        for key in new:
            values.insert(key, np.asarray(points[key], float))
        smoother.update(graph, values, {key: float(stamps[key]) for key in new})
