"""The one filter protocol: declared parameters, an engine over Monte Carlo runs, the one run loop.

A filter is configured by its declared parameters (``PARAMS``, keyword-only
construction, :class:`replay.util.params.Declared`) and run on a
:class:`replay.model.Model` for M Monte Carlo runs at once (a single run is
M = 1). :meth:`Filter.engine` builds the engine of M runs (one
``numpy.random.Generator`` per run):

* ``start(X0 (M, nx), P0 (M, nx, nx))``
* ``step(k, Z_k (Ma, nz), finite (Ma, nz)) -> x (Ma, nx), P (Ma, nx, nx), nis (Ma,), nis_dof (Ma,)``
  over the Ma active runs (NaN components of ``Z_k`` are missing; nis NaN and
  dof 0 where the filter records no normalised innovation squared)
* ``keep(ok (Ma,) bool)``: drop the runs that diverged
* ``finish(m, info)``: diagnostics of run m (index among the M runs) into ``info``
* optional ``run_all(Z (M, n, nz), finite (M, n, nz))``: every step of every run at once
  (the careless pass; ``finite``: the measured components), giving the numbers of the steps:
  ``(X, P, nis, dof)`` stacks, or False (a run failed: the loop redoes it step by step), or
  None (no such path for this model or these measurements); it may set ``engine.seconds``, the
  time of its computation alone (not the one-time loading of compiled code), for the time per step

:meth:`Filter.run_batch` is the one loop over steps (:meth:`Filter.run` is the
batch of one). Time convention: ``x0, P0`` describe the state one step before
the first measurement; step k = 0..n-1 predicts with ``f(., k)`` and updates
with ``z[k]``; estimates are the posterior mean and covariance at each step.

Divergence is per run: a non-finite mean or covariance, or a negative variance, at step k
makes that run's ``diverged_at = k`` (its estimates from k on are NaN) and drops it from the
engine; the other runs go on. A numerical exception (LinAlgError, FloatingPointError,
ValueError, IndexError, ...) raised by ``start`` or ``step`` while several runs are active
redoes the whole call run by run (M = 1 each) from the generators' saved starting states, so a
run's numbers never depend on which runs share its batch; with one run it marks that run
diverged at k with ``info["error"] = "<Type>: <message>"``. Errors of the user (ReplayError) and
of the program (TypeError, AttributeError, ...) are raised, never counted as divergence. (The
loop first runs without per-step tests and checks all estimates once at the end; a run that
diverged or raised is redone, checked at every step, from the saved states.)

Exactness rule for every engine: each run draws only from its own generator
and every operation acts on each run's slice alone, so a batch of M runs gives
the numbers of M runs of one, bit for bit.

Filters written per run (a mutable :class:`State` per run) define ``start(state, x0, P0)``,
``predict(state, k)``, ``update(state, z, k, mask)``, ``estimate(state)`` and ``finish(state,
info)``; the default :meth:`engine` loops over the runs calling them (:class:`PerRunEngine`).
Such an ``update`` reports its innovation as ``state.innovation = (y, S)``: the engine records
NIS = yᵀ S⁻¹ y with len(y) degrees of freedom for that step (NaN where it is not set).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from math import isfinite
from time import perf_counter

import numpy as np

from replay.util.errors import ProtocolError, ReplayError
from replay.util.params import Declared

from . import compiled, gating, noise_params  # noqa: F401  compiled: numba's cache written one process at a time

PER_RUN = ("start", "predict", "update", "estimate", "finish")
# errors of the user or of the program: raised, never counted as a divergence
NOT_NUMERICAL = (ReplayError, TypeError, AttributeError, NameError, NotImplementedError, AssertionError)


@dataclass
class Estimates:
    """Posterior means ``x`` (n, nx), covariances ``P`` (n, nx, nx), seconds per step."""

    x: np.ndarray
    P: np.ndarray
    step_seconds: np.ndarray
    diverged_at: int | None = None
    info: dict = field(default_factory=dict)

    @property
    def diverged(self) -> bool:
        return self.diverged_at is not None

    @property
    def us_per_step(self) -> float:
        s = self.step_seconds[np.isfinite(self.step_seconds)]
        return float(np.median(s) * 1e6) if len(s) else float("nan")


class State:
    """Mutable per-run filter state (mean, covariance, particles, rng, ...)."""

    def __init__(self, model, rng):
        self.model = model
        self.rng = rng


class _Redo(Exception):
    """A numerical exception with several runs active: redo the batch run by run."""


class _Careful(Exception):
    """A divergence or exception in a careless pass: redo it checking every step."""


def numerical(err: BaseException) -> bool:
    """True when ``err`` is a numerical failure of a run (counted as divergence); an exhausted
    memory is not (it is the run's failure, "out of memory")."""
    return isinstance(err, Exception) and not isinstance(err, NOT_NUMERICAL + (MemoryError,))


def _escalate(err: Exception, careful: bool, active: int) -> None:
    """What an exception raised by an engine means: a program or user error is raised as it is;
    in the careless pass, redo carefully (_Careful); with several runs active, redo them one by
    one (_Redo: also after a MemoryError, as one run needs less); returns only when it is the
    divergence of the one active run."""
    if isinstance(err, MemoryError) and active > 1:
        raise _Redo from err
    if not numerical(err):
        raise err
    if not careful:
        raise _Careful from err
    if active > 1:
        raise _Redo from err


class Filter(Declared):
    """Base class of every filter (see the module docstring)."""

    KIND = "filter"
    name = "filter"
    PARAMS = noise_params.NOISE_PARAMS
    q_scale = r_scale = p0_scale = 1.0  # the defaults, for filters with a constructor of their own
    Q = R = P0 = None

    def __init_subclass__(cls, **kwargs):
        """Every filter, built-in or plugin, takes the per-filter noise settings
        (:mod:`replay.filters.noise_params`): added to its ``PARAMS``, taken from the keywords
        of a constructor of its own, reported by a ``params()`` of its own."""
        super().__init_subclass__(**kwargs)
        cls.PARAMS = noise_params.declared(cls)
        if "__init__" in vars(cls):
            cls.__init__ = noise_params.taking_settings(cls.__init__)
        if "params" in vars(cls):
            cls.params = noise_params.reporting_settings(cls.params)

    def params(self) -> dict:
        """The filter's parameters, for manifests and leaderboards; the noise settings only
        where they differ from the defaults (the hash of a configuration without them unchanged).

        A filter whose own constructor sets public attributes that are not in
        ``PARAMS`` (not declared) reports its public attributes.
        """
        public = {k: v for k, v in vars(self).items() if not k.startswith("_")}
        names = {p.name for p in self.PARAMS}
        if set(public) <= names and all(hasattr(self, n) for n in names):
            public = super().params()
        return noise_params.reported(public, self)

    # --- the engine of M runs (override for filters written over the run axis) --------
    def engine(self, model, rngs):
        """The engine of ``len(rngs)`` runs; by default :class:`PerRunEngine` over the per-run methods."""
        return PerRunEngine(self, model, rngs)

    def overrides(self, cls, names=PER_RUN) -> bool:
        """True when this filter's class overrides one of the methods ``names`` defined by ``cls``."""
        return any(getattr(type(self), n) is not getattr(cls, n) for n in names)

    # --- per-run methods (filters written per run) --------------------------------------
    def start(self, state: State, x0: np.ndarray, P0: np.ndarray) -> None:
        state.x = np.array(x0, dtype=float)
        state.P = np.array(P0, dtype=float)

    def predict(self, state: State, k: int) -> None:
        raise NotImplementedError

    def update(self, state: State, z: np.ndarray, k: int, mask) -> None:
        raise NotImplementedError

    def estimate(self, state: State):
        return state.x, state.P

    def finish(self, state: State, info: dict) -> None:
        """Add run diagnostics to ``info`` (e.g. resampling counts)."""

    # --- the run loop ---------------------------------------------------------------------
    def run(self, model, z, x0, P0, rng: np.random.Generator | None = None) -> Estimates:
        """One run: the batch of one."""
        z = np.asarray(z, dtype=float)
        return self.run_batch(
            model,
            z[None],
            np.asarray(x0, float)[None],
            np.asarray(P0, float)[None],
            [rng if rng is not None else np.random.default_rng(0)],
        )[0]

    def run_batch(self, model, Z, X0, P0, rngs) -> list[Estimates]:
        """M runs: measurements ``Z`` (M, n, nz), priors ``X0`` (M, nx), ``P0`` (M, nx, nx), one
        generator per run (None: ``default_rng(0)``). One Estimates per run (module docstring)."""
        Z, X0, P0 = (np.asarray(a, dtype=float) for a in (Z, X0, P0))
        M, nx = len(Z), model.nx
        if Z.ndim != 3 or X0.shape != (M, nx) or P0.shape != (M, nx, nx) or len(rngs) != M:
            raise ValueError(
                f"run_batch: Z {Z.shape}, X0 {X0.shape}, P0 {P0.shape} and {len(rngs)} "
                f"generators must describe the same runs of a model with nx = {nx}"
            )
        rngs = [g if g is not None else np.random.default_rng(0) for g in rngs]
        saved = [g.bit_generator.state for g in rngs]

        def restore():
            for g, state in zip(rngs, saved):
                g.bit_generator.state = state

        try:
            try:
                return self._loop(model, Z, X0, P0, rngs, careful=False)
            except _Careful:
                restore()
                return self._loop(model, Z, X0, P0, rngs, careful=True)
        except _Redo:
            restore()
            return [
                self._loop(model, Z[m : m + 1], X0[m : m + 1], P0[m : m + 1], rngs[m : m + 1], careful=True)[0]
                for m in range(M)
            ]

    def _loop(self, model, Z, X0, P0, rngs, careful: bool) -> list[Estimates]:
        """The steps of M runs. Careless first (no per-step test: most runs never diverge), checked
        once at the end; any divergence or exception -> _Careful: the caller redoes it carefully,
        dropping each run where it diverges (_Redo: run by run, after an exception)."""
        M, n = Z.shape[:2]
        nx = model.nx
        diverged, errors = [None] * M, {}
        finite = np.isfinite(Z)
        active = np.arange(M)
        try:
            engine = self.engine(model, rngs)
        except MemoryError as err:
            _escalate(err, careful, M)
        gating.check(self, engine, model)
        started = True
        try:
            engine.start(X0, P0)
        except Exception as err:
            _escalate(err, careful, M)
            diverged[0], errors[0], active, started = 0, err, active[:0], False
        clock = perf_counter
        done = None
        if not careful and started and hasattr(engine, "run_all"):
            t0 = clock()
            done = engine.run_all(Z, finite)  # every step in one compiled loop, when the engine has one
            if done is False:
                raise _Careful
        if done is not None:  # its arrays are the results: nothing to fill or copy
            X, P, nis, dof = done
            if getattr(X, "shape", None) != (M, n, nx) or getattr(P, "shape", None) != (M, n, nx, nx):
                raise shape_error(self, "run_all()", (M, n, nx), X, P)
            secs = np.full((M, n), getattr(engine, "seconds", clock() - t0) / (n * M))
            active = active[:0]
        else:
            X, P = np.full((M, n, nx), np.nan), np.full((M, n, nx, nx), np.nan)
            secs, nis, dof = np.full((M, n), np.nan), np.full((M, n), np.nan), np.zeros((M, n), int)
        for k in range(n):
            na = len(active)
            if not na:
                break
            rows = slice(None) if na == M else active
            t0 = clock()
            try:
                xk, Pk, nk, dk = engine.step(k, Z[rows, k], finite[rows, k])
            except Exception as err:
                _escalate(err, careful, na)
                diverged[active[0]], errors[active[0]] = k, err
                break
            dt = (clock() - t0) / na
            if getattr(xk, "shape", None) != (na, nx) or getattr(Pk, "shape", None) != (na, nx, nx):
                raise shape_error(self, "its engine's step()", (na, nx), xk, Pk)
            if not careful or _all_fine(xk, Pk):
                X[rows, k], P[rows, k], secs[rows, k], nis[rows, k], dof[rows, k] = xk, Pk, dt, nk, dk
                continue
            d = Pk.diagonal(0, 1, 2)
            ok = np.isfinite(xk).all(axis=1) & np.isfinite(Pk).all(axis=(1, 2)) & (d >= 0.0).all(axis=1)
            good = active[ok]
            X[good, k], P[good, k], secs[good, k], nis[good, k], dof[good, k] = xk[ok], Pk[ok], dt, nk[ok], dk[ok]
            for m in active[~ok]:
                diverged[m] = k
            active = good
            engine.keep(ok)
        if not careful and not (
            np.isfinite(X).all() and np.isfinite(P).all() and P.diagonal(0, 2, 3).min(initial=0.0) >= 0.0
        ):
            raise _Careful
        out = []
        for m in range(M):
            info = {"nis": nis[m], "nis_dof": dof[m]}
            if started:
                engine.finish(m, info)
            if m in errors:
                info["error"] = f"{type(errors[m]).__name__}: {errors[m]}"
            out.append(Estimates(X[m], P[m], secs[m], diverged[m], info))
        return out


def shape_error(flt, where: str, want: tuple, x, P) -> ProtocolError:
    """One line naming the filter (a name, or its class when it has no ``name`` of its own) and the
    shapes expected and got (the protocol boundary)."""
    got = f"a state of shape {np.shape(x)} and a covariance of shape {np.shape(P)}"
    cls = flt if isinstance(flt, type) else type(flt)
    who = repr(flt) if isinstance(flt, str) else repr(cls.name) if "name" in vars(cls) else cls.__name__
    return ProtocolError(
        f"filter {who}: {where} returned {got}; expected {want} and {want + want[-1:]} "
        f"(a state of {want[-1]} components)"
    )


def check_batch(name: str, out, problems) -> None:
    """What ``run_batch`` returned for ``problems``: one :class:`Estimates` per run, means (n, nx) and
    covariances (n, nx, nx) at most as long as the measurements (else one-line ProtocolError)."""
    if not isinstance(out, (list, tuple)) or len(out) != len(problems):
        got = f"{len(out)} results" if isinstance(out, (list, tuple)) else f"a {type(out).__name__}"
        raise ProtocolError(
            f"filter {name!r}: run_batch() returned {got} for {len(problems)} runs (expected one Estimates per run)"
        )
    for est, p in zip(out, problems):
        n, nx = len(p.z), p.model.nx
        x, P = getattr(est, "x", None), getattr(est, "P", None)
        if np.ndim(x) != 2 or len(x) > n or np.shape(x)[1:] != (nx,) or np.shape(P) != (len(x), nx, nx):
            raise shape_error(name, "run_batch()", (n, nx), x, P)


def on_points(fun, X, k):
    """``fun`` (model.f or model.h) on points (..., m, nx) (sigma points, particles of M runs),
    called on their (-1, nx) view: numpy's elementwise kernels cost less on 2-d arrays."""
    if X.ndim == 2:
        return fun(X, k)
    return fun(X.reshape(-1, X.shape[-1]), k).reshape(X.shape[:-1] + (-1,))


def _all_fine(x, P) -> bool:
    """True when every run's mean and covariance are finite with non-negative variances.

    False may be a false alarm (a sum overflowing); the caller then checks run by run.
    """
    if len(x) == 1:  # one run: Python floats beat numpy's per-call cost on a few numbers
        p = P.ravel().tolist()
        return isfinite(sum(p) + sum(x.ravel().tolist())) and min(p[:: len(P[0]) + 1]) >= 0.0
    return isfinite(x.sum() + P.sum()) and P.diagonal(0, 1, 2).min() >= 0.0


class PerRunEngine:
    """Default engine: one :class:`State` per run, the filter's per-run methods on each.

    A numerical exception in one run marks that run (NaN estimate: diverged at
    that step, ``info["error"]``); the other runs go on.
    """

    def __init__(self, flt, model, rngs):
        self.flt, self.model = flt, model
        self.states = [State(model, g) for g in rngs]
        self.errors = {}

    def start(self, X0, P0):
        self.ids = np.arange(len(self.states))
        for m, s in enumerate(self.states):
            self.flt.start(s, X0[m], P0[m])

    def keep(self, ok):
        self.ids = self.ids[ok]

    def step(self, k, Z, finite):
        flt, nx = self.flt, self.model.nx
        Ma = len(self.ids)
        x, P = np.full((Ma, nx), np.nan), np.full((Ma, nx, nx), np.nan)
        nis, dof = np.full(Ma, np.nan), np.zeros(Ma, int)
        for j, m in enumerate(self.ids):
            state, f = self.states[m], finite[j]
            try:
                flt.predict(state, k)
                state.innovation = None
                if f.all():
                    flt.update(state, Z[j], k, None)
                elif f.any():
                    flt.update(state, Z[j], k, f)
                if state.innovation is not None:  # the filter reported (y, S): module docstring
                    y, S = (np.asarray(a, float) for a in state.innovation)
                    nis[j], dof[j] = float(y @ np.linalg.solve(S, y)), len(y)
                xe, Pe = flt.estimate(state)
                if np.shape(xe) != (nx,) or np.shape(Pe) != (nx, nx):
                    raise shape_error(flt, "estimate()", (nx,), xe, Pe)
                x[j], P[j] = xe, Pe
            except Exception as err:
                if not numerical(err):
                    raise
                self.errors[m] = err  # left NaN: the loop marks the run diverged at k
        return x, P, nis, dof

    def finish(self, m, info):
        self.flt.finish(self.states[m], info)
        if m in self.errors:
            err = self.errors[m]
            info["error"] = f"{type(err).__name__}: {err}"
