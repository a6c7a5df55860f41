"""Negative log-likelihood of a Kalman filter's innovations, on a linear-Gaussian model.

For a Kalman filter on x_k = F x_{k-1} + w (Q), z_k = H x_k + v (R), the innovation
y_k is N(0, S_k) with S_k = H (F P_{k-1} F' + Q) H' + R, so a run's

    nll = 1/2 sum_k (y_k' S_k^-1 y_k + log det S_k + d_k log 2 pi)

over the steps with a measurement (d_k components). The first term is the NIS the
filter records; S_k is rebuilt here from the filter's own posterior covariances P_{k-1}
(P0 at the first step) and the model: exact for ``kf``, ``ekf``, ``ukf`` and ``ckf``
on a linear model (all four are the Kalman filter there), so nothing in the filters
changes. Other filters or models: no ``nll`` (``replay tune`` refuses the objective).
A filter with its own noise settings (``q_scale``, ``R``, ...: :mod:`replay.filters.noise_params`)
ran on the model and P0 under those settings: ``model`` and ``P0`` here are those (the pipeline
passes them), so the likelihood is that of the filter that ran.
"""

from __future__ import annotations

import numpy as np

from replay.util.kernels import LOG_2PI, gauss_logpdf
from replay.filters import make_filter
from replay.filters.noise_params import apply

NLL_FILTERS = ("kf", "ekf", "ukf", "ckf")  # exact Kalman filters on a linear model


def linear_matrices(model):
    """(F, H, Q, R) of a linear model with constant matrices, else None (:meth:`Model.linear_matrices`)."""
    return model.linear_matrices()


def provides(filter_name: str) -> str | None:
    """None when the filter's runs get an ``nll``; else why not (one phrase)."""
    if filter_name not in NLL_FILTERS:
        return f"only {', '.join(NLL_FILTERS)} record it (the Kalman filters exact on a linear model)"
    return None


def innovation_nll(problem, est, nis, dof, model=None, P0=None) -> float:
    """A run's nll (module docstring), or NaN when the model is not linear or nothing was measured;
    ``model``, ``P0``: what the filter ran on (default: the problem's)."""
    model = problem.model if model is None else model
    mats = linear_matrices(model)
    if mats is None or est.diverged:
        return float("nan")
    F, H, Q, R = mats
    n = len(est.x)
    prev = np.concatenate([np.asarray(problem.P0 if P0 is None else P0, float)[None], est.P[: n - 1]])
    S = H @ (F @ prev @ F.T + Q) @ H.T + R  # (n, nz, nz)
    z = np.asarray(problem.z[:n], float)
    seen = np.isfinite(z)
    steps = np.flatnonzero(np.asarray(dof[:n]) > 0)
    full = steps[seen[steps].all(axis=1)]
    part = steps[~seen[steps].all(axis=1)]
    sign, logdet = np.linalg.slogdet(S[full]) if len(full) else (np.ones(0), np.zeros(0))  # one batched call
    for k in part:  # a partial measurement: its components' block of S
        sk, lk = np.linalg.slogdet(S[k][np.ix_(seen[k], seen[k])])
        sign, logdet = np.append(sign, sk), np.append(logdet, lk)
    used = np.concatenate([full, part])
    if not len(used):
        return float("nan")
    nis = np.asarray(nis, float)[used]
    if (sign <= 0).any() or not np.isfinite(nis).all():
        return float("nan")
    return -float(np.sum(gauss_logpdf(nis + logdet, seen[used].sum(axis=1) * LOG_2PI)))


def of_run(config: dict, problem, est, series) -> dict:
    """``{"nll": ...}`` of one run of ``config`` (a configuration dict) for a filter and model that
    give it, computed under the filter's noise settings; ``{}`` otherwise."""
    if provides(config["filter"]) is not None or linear_matrices(problem.model) is None:
        return {}

    model, P0 = apply(make_filter(config["filter"], **config["filter_params"]), problem.model, problem.P0[None])
    return {"nll": innovation_nll(problem, est, series["nis"], series["nis_dof"], model, P0[0])}
