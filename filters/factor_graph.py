"""Factor-graph smoothing with GTSAM over a whole recording: the rows ``gtsam-batch`` and ``gtsam-lag``.

Replay is offline: the whole recording is known, so the best estimate of the state at a step
uses every measurement, before and after it. These rows compute it on the filters' own problem
(the task's model, measurements, noise and prior: the same inputs every filter gets, the held-out
fixes missing as for them; the reference never reaches them), as a factor graph:

* one variable per step (the model's state vector, ``nx`` numbers; angles unwrapped in the
  variable, wrapped in every residual) and one for the prior state ``x0`` a step before the first;
* a **prior** factor ``x_-1 ~ N(x0, P0)``;
* a **process** factor between consecutive steps, ``x_k - f(x_{k-1}, k) ~ N(0, Q_k)``: the
  model's motion (the fusion task's: the body velocity and rates, measured by the odometry, gyro
  or DVL, integrated through the pose) with its process noise;
* a **measurement** factor at every step with a measured component, ``z_k - h(x_k) ~ N(0,
  R_k)`` on the measured components alone (fixes, depth, attitude, velocities, rates: what the
  step's message measured, with the variance the filters use: the recorded covariance by default).

``gtsam-batch`` minimises the graph's error with Levenberg-Marquardt (relinearised at every
iteration; each iteration's damped linear system ``(J'J + lambda I) d = -J'e`` solved by GTSAM's
sparse elimination, :meth:`gtsam.GaussianFactorGraph.optimize`; lambda as GTSAM's
``LevenbergMarquardtOptimizer`` sets it: 1e-5 at first, times 10 after a rejected step, over 10
after an accepted one), started from the EKF's filtered track; its covariances are GTSAM's
marginals (:class:`gtsam.Marginals`) of the graph linearised at the optimum, for the NEES.
``gtsam-lag`` (:mod:`replay.filters.fixed_lag`) is GTSAM's incremental fixed-lag smoother over the
same factors: causal with a delay.

The optional extra ``replay-nav[smooth]`` installs GTSAM; without it these rows are refused in
one line naming it, and every other row runs.
"""

from __future__ import annotations

import logging

import numpy as np

from replay.util.errors import ReplayError
from replay.util.params import Param

from . import gating
from .base import Estimates, Filter
from .kalman import EKF
from time import perf_counter

INSTALL = 'pip install "replay-nav[smooth]"'


def gtsam_module(name: str):
    """The ``gtsam`` module, or a one-line ReplayError naming the extra that installs it."""
    try:
        # lazy: optional, gtsam is the [smooth] extra: its absence is refused in one line
        import gtsam  # noqa: PLC0415
    except ImportError:
        raise ReplayError(f"filter {name!r} needs GTSAM, which is not installed: {INSTALL}") from None
    return gtsam


def whitener(C):
    """``W`` (..., d, d) with ``W C W' = I`` for covariances ``C`` (..., d, d): the inverse of the
    Cholesky factor. A covariance that is not positive definite is refused."""
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        raise ReplayError("a factor-graph smoother needs positive-definite Q, R and P0 (a covariance is not)") from None
    return np.linalg.inv(L)


def wrap_rows(e, angles):
    """``e`` with the components ``angles`` (of the last axis) wrapped into [-pi, pi)."""
    if len(angles):
        e[..., angles] = (e[..., angles] + np.pi) % (2.0 * np.pi) - np.pi
    return e


class Graph:
    """The factors of one run, evaluated at a stack of states ``X`` (n + 1, nx): ``X[0]`` the prior
    state, ``X[k + 1]`` step k. Every factor of a kind at once (the model's ``at_steps`` where it
    has it, else step by step); the measurement factors grouped by the components they measure."""

    def __init__(self, model, z, x0, P0):
        self.model, self.z, self.x0 = model, np.asarray(z, float), np.asarray(x0, float)
        n = len(self.z)
        self.n, self.nx = n, model.nx
        finite = np.isfinite(self.z)
        self.W0 = whitener(np.asarray(P0, float))
        self.WQ = whitener(_stack(model, "process", n))
        R = _stack(model, "measurement", n)
        self.groups = []  # (steps, measured components, whiteners (len(steps), d, d))
        patterns, which = np.unique(finite, axis=0, return_inverse=True)
        for g, mask in enumerate(patterns):
            cols = np.flatnonzero(mask)
            steps = np.flatnonzero(which.ravel() == g)
            if len(cols) and len(steps):
                self.groups.append((steps, cols, whitener(R[steps][:, cols][:, :, cols])))
        self.x_angles = list(getattr(model, "x_angles", ()))
        self.z_angles = list(getattr(model, "z_angles", ()))
        self.all_steps = np.arange(n)
        self._params = {}

    def by_step(self) -> dict:
        """step -> (measured components, whitener of their R) of every step with a measurement."""
        return {int(k): (cols, W[i]) for steps, cols, W in self.groups for i, k in enumerate(steps)}

    def _at(self, name, X, steps):
        if hasattr(self.model, "at_steps"):
            key = (id(steps), len(steps))
            if key not in self._params:
                self._params[key] = (steps, self.model.step_params(steps))  # steps kept: its id stays theirs
            return self.model.at_steps(name, X, self._params[key][1])
        return np.stack([np.asarray(getattr(self.model, name)(X[i], int(k)), float) for i, k in enumerate(steps)])

    def process(self, X, jacobians=True):
        """Whitened residuals (n, nx) of the process factors and, with ``jacobians``, their Jacobians
        wrt x_{k-1} (n, nx, nx) (wrt x_k: the whitener ``WQ``)."""
        f = self._at("f", X[:-1], self.all_steps)
        e = np.einsum("kij,kj->ki", self.WQ, wrap_rows(X[1:] - f, self.x_angles))
        if not jacobians:
            return e
        return e, -np.einsum("kij,kjl->kil", self.WQ, self._at("F", X[:-1], self.all_steps))

    def measurement(self, X, jacobians=True):
        """Per group: (steps, whitened residuals (m, d)[, Jacobians wrt x_k (m, d, nx)])."""
        out = []
        angles = np.zeros(self.z.shape[1], bool)
        angles[self.z_angles] = True
        for steps, cols, W in self.groups:
            h = self._at("h", X[steps + 1], steps)
            e = h[:, cols] - self.z[steps][:, cols]
            e = wrap_rows(e, list(np.flatnonzero(angles[cols])))
            e = np.einsum("kij,kj->ki", W, e)
            if jacobians:
                H = self._at("H", X[steps + 1], steps)[:, cols]
                out.append((steps, e, np.einsum("kij,kjl->kil", W, H)))
            else:
                out.append((steps, e))
        return out

    def prior(self, X):
        return self.W0 @ wrap_rows(X[0] - self.x0, self.x_angles)

    def error(self, X) -> float:
        """Half the sum of the squared whitened residuals at ``X``."""
        total = np.sum(self.prior(X) ** 2) + np.sum(self.process(X, False) ** 2)
        total += sum(np.sum(m[1] ** 2) for m in self.measurement(X, False))
        return 0.5 * float(total)

    def linear(self, gtsam, X):
        """The graph linearised at ``X``: a :class:`gtsam.GaussianFactorGraph` over keys 0..n
        (``A d = b`` with ``b = -e``, whitened: unit noise)."""
        g = gtsam.GaussianFactorGraph()
        unit = {}

        def noise(d):
            if d not in unit:
                unit[d] = gtsam.noiseModel.Unit.Create(d)
            return unit[d]

        add, J = g.add, gtsam.JacobianFactor
        add(J(0, self.W0, -self.prior(X), noise(self.nx)))
        e, A = self.process(X)
        unit_x = noise(self.nx)
        for k in range(self.n):
            add(J(k, A[k], k + 1, self.WQ[k], -e[k], unit_x))
        for steps, e, H in self.measurement(X):
            d = noise(e.shape[1])
            for i, k in enumerate(steps):
                add(J(int(k) + 1, H[i], -e[i], d))
        return g


def _stack(model, kind: str, n: int):
    """Q_k or R_k of every step (n, d, d): the model's stack where it has one, else per step."""
    many = getattr(model, f"{kind}_covs", None)
    if many is not None:
        return np.asarray(many(n), float)
    one = getattr(model, f"{kind}_cov")
    return np.stack([np.asarray(one(k), float) for k in range(n)])


def levenberg_marquardt(gtsam, graph: Graph, X, max_iterations: int, tolerance: float):
    """(X at the minimum, its linearised graph, iterations, converged): GTSAM's LM schedule (module
    docstring) over our relinearisation; converged when an accepted step lowers the error by less
    than ``tolerance`` (relative) or lambda passes 1e5 (no step lowers it); else the iterations ran out."""
    lam, err = 1e-5, graph.error(X)
    it, converged = 0, False
    lin = graph.linear(gtsam, X)
    unit, zero = gtsam.noiseModel.Unit.Create(graph.nx), np.zeros(graph.nx)
    order = gtsam.Ordering()  # along the chain: no fill-in, no COLAMD at every iteration
    for key in range(graph.n + 1):
        order.push_back(key)
    for it in range(1, max_iterations + 1):
        damped = lin.clone()
        root = np.sqrt(lam) * np.eye(graph.nx)
        for key in range(graph.n + 1):
            damped.add(gtsam.JacobianFactor(key, root, zero, unit))
        delta = damped.optimize(order)
        step = np.stack([delta.at(key) for key in range(graph.n + 1)])
        trial = X + step
        new = graph.error(trial) if np.isfinite(step).all() else np.inf
        if new <= err:
            X, done = trial, err - new <= tolerance * max(err, 1e-300)
            err, lam = new, max(lam / 10.0, 1e-12)
            lin = graph.linear(gtsam, X)
            if done:
                converged = True
                break
        else:
            lam *= 10.0
            if lam > 1e5:
                converged = True
                break
    return X, lin, it, converged


def marginals(gtsam, lin, n: int, nx: int):
    """(n, nx, nx) marginal covariances of the states of steps 0..n-1 (keys 1..n) of ``lin``."""
    solution = gtsam.VectorValues()
    for key in range(n + 1):
        solution.insert(key, np.zeros(nx))
    m = gtsam.Marginals(lin, solution)
    return np.stack([m.marginalCovariance(key) for key in range(1, n + 1)])


class Smoother(Filter):
    """A row computed over the whole run at once (not a causal filter): :meth:`run_batch` solves each
    distinct run once (a recording's runs are identical unless the task draws noise: the same
    measurements, prior and model give the same numbers, so a repeat is the first one's copy)."""

    name = "smoother"

    def __init__(self, **params):
        gtsam_module(self.name)  # refused when made, before any row runs: one line naming the extra
        super().__init__(**params)

    def engine(self, model, rngs):
        raise ReplayError(f"filter {self.name!r} is a smoother: it runs over the whole recording (run_batch)")

    def solve(self, model, z, x0, P0):
        """(X (n, nx), P (n, nx, nx), info) of one run."""
        raise NotImplementedError

    def run_batch(self, model, Z, X0, P0, rngs) -> list[Estimates]:
        if gating.active(model) is not None:
            raise ReplayError(f"filter {self.name!r} cannot gate measurements: remove the rejection_threshold")

        out, seen = [], []
        for m in range(len(Z)):
            same = next((e for (z, x, p, e) in seen if _equal(z, Z[m]) and _equal(x, X0[m]) and _equal(p, P0[m])), None)
            if same is None:
                t0 = perf_counter()
                X, P, info = self.solve(model, Z[m], X0[m], P0[m])
                secs = np.full(len(X), (perf_counter() - t0) / max(len(X), 1))
                info.setdefault("nis", np.full(len(X), np.nan))
                info.setdefault("nis_dof", np.zeros(len(X), int))
                same = Estimates(X, P, secs, None, info)
                seen.append((Z[m], X0[m], P0[m], same))
            out.append(Estimates(same.x.copy(), same.P.copy(), same.step_seconds.copy(), None, dict(same.info)))
        return out


def _equal(a, b) -> bool:
    return np.array_equal(a, b, equal_nan=True)


def initial_track(model, z, x0, P0):
    """(n + 1, nx) starting states: x0, then the EKF's filtered means (the motion model alone from
    where the EKF diverged, if it did)."""
    est = EKF().run(model, z, x0, P0)
    X = np.vstack([np.asarray(x0, float)[None], est.x])
    for k in range(len(z)):
        if not np.isfinite(X[k + 1]).all():
            X[k + 1] = model.f(X[k], k)
    return X


class GtsamBatch(Smoother):
    """Smoother (not causal): the MAP track of the whole run, a factor graph by Levenberg-Marquardt (GTSAM)."""

    name = "gtsam-batch"
    OFFLINE = True  # uses every measurement of a run: the gap columns measure the filters against it
    PARAMS = (
        Param("max_iterations", int, 50, "Levenberg-Marquardt iterations at most", low=1),
        Param(
            "tolerance",
            float,
            1e-6,
            "stop when an accepted step lowers the error by less than this share",
            low=0.0,
            low_open=True,
        ),
    )

    def solve(self, model, z, x0, P0):
        gtsam = gtsam_module(self.name)
        graph = Graph(model, z, x0, P0)
        X = initial_track(model, z, x0, P0)
        start = graph.error(X)
        X, lin, iterations, converged = levenberg_marquardt(gtsam, graph, X, self.max_iterations, self.tolerance)
        if not converged:  # the best track found, not the optimum: said, not hidden
            logging.getLogger("replay").warning(
                f"filter {self.name!r}: Levenberg-Marquardt did not converge in {iterations} iterations "
                "(max_iterations): its track is the best found, not the optimum"
            )
        P = marginals(gtsam, lin, graph.n, graph.nx)
        x = wrap_rows(X[1:].copy(), graph.x_angles)
        info = {
            "iterations": iterations,
            "converged": converged,
            "graph_error_start": start,
            "graph_error": graph.error(X),
        }
        return x, P, info
