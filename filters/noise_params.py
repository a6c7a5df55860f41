"""Per-filter noise settings: each filter configuration may carry its own Q, R and P0.

A task gives every filter the same model noise (Q_k, R_k) and prior covariance P0. Six
parameters, declared here once and added to the ``PARAMS`` of every
:class:`replay.filters.base.Filter` subclass (built-in or plugin,
:meth:`~replay.filters.base.Filter.__init_subclass__`), let one configuration use its own:

* ``q_scale``, ``r_scale``, ``p0_scale`` (> 0, default 1): multiply Q_k (at every step: a
  model's own ``process_cov(k)`` too), R_k and P0;
* ``Q``, ``R``, ``P0`` (default null): replace them: a full matrix (list of rows), its diagonal
  (a list of positive numbers) or a positive scalar (times the identity); symmetric positive
  definite, checked when the filter is made; the size is known only once the task is built
  (:func:`check`, before any filter runs). A replacement of Q or R needs a time-invariant
  model (one whose ``process_cov``/``measurement_cov`` is not its own). A scale and a
  replacement together: the replacement times the scale.

Only settings that differ from the defaults appear in a filter's ``params()``, so the
configuration hash and the leaderboard ``params`` of a configuration without them are
what they were before these parameters existed. :func:`apply` gives the filter its
problem's model with the new noise (a shallow copy: the task's model, its prior and the
reference are never changed) and the prior covariances; without settings it returns
its inputs themselves (same numbers, no cost).

A model that draws its own process noise (its own ``sample_f``) or weighs its own
likelihood (its own ``loglik``) derives them from ``Q``/``R`` in its own way: it takes
new ones only when it defines ``refresh_noise()`` (recompute what it derives from
``self.Q`` and ``self.R``); otherwise a setting that changes them is refused.
"""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass

import numpy as np

from replay.model import Model
from replay.util.covariance import Covariance
from replay.util.errors import ReplayError
from replay.util.params import Param, _is_number


@dataclass(frozen=True)
class NoiseMatrix(Covariance):
    """A :class:`Covariance` of a size known only once the task is built, or a positive scalar
    (that times the identity)."""

    def accepts(self) -> str:
        return (
            "a symmetric positive-definite matrix (list of rows), its diagonal (positive numbers) "
            "or a positive number (times the identity)" + (" (or null)" if self.optional else "")
        )

    def _coerce(self, v):
        if _is_number(v):
            return math.isfinite(v) and v > 0, float(v)
        return super()._coerce(v)


SCALE = dict(low=0.0, low_open=True)
NOISE_PARAMS = (
    Param("q_scale", float, 1.0, "multiplies the task's process noise covariance Q_k at every step", **SCALE),
    Param("r_scale", float, 1.0, "multiplies the task's measurement noise covariance R_k", **SCALE),
    Param("p0_scale", float, 1.0, "multiplies the task's prior covariance P0", **SCALE),
    NoiseMatrix("Q", list, None, "replaces the task's process noise covariance (time-invariant models)", optional=True),
    NoiseMatrix(
        "R", list, None, "replaces the task's measurement noise covariance (time-invariant models)", optional=True
    ),
    NoiseMatrix("P0", list, None, "replaces the task's prior covariance", optional=True),
)
NAMES = tuple(p.name for p in NOISE_PARAMS)
DEFAULTS = {p.name: p.default for p in NOISE_PARAMS}


def settings(flt) -> dict:
    """The filter's noise settings that differ from the defaults (JSON-plain: lists of lists)."""
    out = {}
    for name in NAMES:
        v = getattr(flt, name, DEFAULTS[name])
        if v != DEFAULTS[name]:
            out[name] = [list(r) if isinstance(r, tuple) else r for r in v] if isinstance(v, tuple) else v
    return out


def declared(cls) -> tuple:
    """``cls.PARAMS`` followed by the noise settings (once); a parameter of its own with one of
    their names is refused (TypeError, when the class is defined)."""
    own = tuple(p for p in cls.PARAMS if p not in NOISE_PARAMS)
    if clash := [p.name for p in own if p.name in NAMES]:
        raise TypeError(
            f"filter {cls.__name__}: parameter {clash[0]!r} is reserved for the per-filter "
            "noise settings (replay.filters.noise_params); rename it"
        )
    return own + NOISE_PARAMS


def taking_settings(init):
    """A filter's constructor of its own, also taking the noise settings (checked, one line)."""

    @functools.wraps(init)
    def __init__(self, *args, **kwargs):
        given = {k: kwargs.pop(k) for k in NAMES if k in kwargs}
        init(self, *args, **kwargs)
        for p in NOISE_PARAMS:
            if p.name in given:
                setattr(self, p.name, p.check(given[p.name], self.owner()))

    return __init__


def reporting_settings(params):
    """A filter's ``params()`` of its own, reporting the noise settings as :func:`reported`."""

    @functools.wraps(params)
    def wrapped(self) -> dict:
        return reported(params(self), self)

    return wrapped


def reported(params: dict, flt) -> dict:
    """``params`` with the noise settings of ``flt`` where they differ from the defaults only."""
    return {**{k: v for k, v in params.items() if k not in NAMES}, **settings(flt)}


def matrix(value, n: int, who: str, name: str) -> np.ndarray:
    """A checked :class:`NoiseMatrix` value as an n x n array; another size: one line."""
    M = np.asarray(value, float)
    if M.ndim == 0:
        return float(M) * np.eye(n)
    if len(M) != n:
        raise ReplayError(
            f"{who}: {name} must be {n}x{n} (this task's model has {n} "
            f"{'state' if name != 'R' else 'measurement'} components), or its diagonal "
            f"({n} numbers), or a number; got size {len(M)}"
        )
    return np.diag(M) if M.ndim == 1 else M


def _own(model, method: str) -> bool:
    return getattr(type(model), method) is not getattr(Model, method)


def check(flt, model) -> None:
    """Refuse (one line naming the filter and parameter) settings this model cannot take."""
    plan(flt, model)


def plan(flt, model) -> dict:
    """What to change: {"Q"/"R": (matrix or None, scale), "P0": (matrix or None, scale)}."""
    s = settings(flt)
    if not s:
        return {}
    who = f"filter {getattr(flt, 'name', type(flt).__name__)!r}"
    nx = model.nx
    out = {}
    for name, cov, draw, n in (("Q", "process_cov", "sample_f", nx), ("R", "measurement_cov", "loglik", model.nz)):
        scale = s.get(name.lower() + "_scale", 1.0)
        if name not in s and scale == 1.0:
            continue
        given = s.get(name)
        if given is not None and _own(model, cov):
            raise ReplayError(
                f"{who}: {name} cannot replace the noise of model {type(model).__name__}, whose "
                f"{cov}(k) changes with the step; use {name.lower()}_scale"
            )
        if _own(model, draw) and not hasattr(model, "refresh_noise"):
            raise ReplayError(
                f"{who}: model {type(model).__name__} computes its own {draw} from its noise; "
                f"{name} and {name.lower()}_scale cannot change it (it defines no refresh_noise)"
            )
        out[name] = (None if given is None else matrix(given, n, who, name), scale)
    if "P0" in s or "p0_scale" in s:
        out["P0"] = (None if s.get("P0") is None else matrix(s["P0"], nx, who, "P0"), s.get("p0_scale", 1.0))
    return out


class _Scaled:
    """``process_cov``/``measurement_cov`` of a time-varying model times a scale (or its stack of
    every step, ``process_covs``/``measurement_covs``: the same products)."""

    def __init__(self, fun, scale: float):
        self.fun, self.scale = fun, scale

    def __call__(self, k):
        return self.fun(k) * self.scale


def apply(flt, model, P0):
    """``(model, P0)`` for this filter: its noise settings applied (module docstring); the same
    objects when it has none. ``P0``: the runs' prior covariances (M, nx, nx)."""
    todo = plan(flt, model)
    if not todo:
        return model, P0
    if "Q" in todo or "R" in todo:
        model = _noisy(model, todo)
    if "P0" in todo:
        given, scale = todo["P0"]
        P0 = np.broadcast_to(given, np.shape(P0)).copy() if given is not None else P0
        P0 = P0 * scale if scale != 1.0 else P0
    return model, P0


def _noisy(model, todo: dict):
    """A shallow copy of ``model`` whose Q, R (and process_cov, measurement_cov) are the new ones."""
    new = copy.copy(model)
    for name, cov in (("Q", "process_cov"), ("R", "measurement_cov")):
        if name not in todo:
            continue
        given, scale = todo[name]
        base = given if given is not None else np.asarray(getattr(model, name), float)
        setattr(new, name, base * scale if scale != 1.0 else base)
        if _own(model, cov):  # time-varying (a replacement was refused): its own values, scaled
            setattr(new, cov, _Scaled(getattr(model, cov), scale))
            if hasattr(model, cov + "s"):  # its stack of every step (the run loops'), scaled alike
                setattr(new, cov + "s", _Scaled(getattr(model, cov + "s"), scale))
    if hasattr(new, "refresh_noise"):
        new.refresh_noise()
    return new
