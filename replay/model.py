"""The model protocol shared by every filter.

A model is the discrete-time state-space system

    x_k = f(x_{k-1}, k) + w_k,   w_k ~ N(0, Q_k)
    z_k = h(x_k, k) + v_k,       v_k ~ N(0, R_k)

``f`` and ``h`` take arrays of states of shape ``(..., nx)`` — one state, the
sigma points of a UKF, the cubature points of a CKF, the particles of a PF, or
all of them for many Monte Carlo runs at once — and return ``(..., nx)`` and
``(..., nz)``. Filters never loop over points in Python.

Angles are declared: ``x_angles`` and ``z_angles`` list the state and
measurement components that are angles (radians). Filters form residuals of
those components with :func:`replay.util.angles.residual` and means with
:func:`replay.util.angles.weighted_mean`.

Jacobians ``F`` and ``H`` are optional; the defaults are central differences
(also vectorised: all ``2 nx`` perturbed states go through ``f`` at once).
Filters know nothing of files, datasets or the CLI: they see a model and
measurements only.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from replay.util import kernels
from replay.util.angles import angle_mask, residual, wrap
from replay.util.linalg import cholesky

_NO_FACTOR, _NO_VAR = np.eye(1), np.ones(1)  # unused operands of the compiled likelihood


class Model:
    """Base class: subclasses set ``nx``, ``nz``, ``Q``, ``R`` and define ``f``, ``h``."""

    nx: int
    nz: int
    x_angles: tuple[int, ...] = ()
    z_angles: tuple[int, ...] = ()
    Q: np.ndarray
    R: np.ndarray
    jacobian_step: float = 1e-6
    vector_jacobians: bool = False  # True when F and H also take stacks of states (..., nx)
    # Sigma-point filters: the predicted mean is f(mean) and the points give only the covariance,
    # about it (UKF-M, Brossard, Barrau & Bonnabel 2020), for a dead-reckoned pose (replay.models.kinematic)
    mean_at_f: bool = False

    # --- dynamics and measurement -------------------------------------------------
    def f(self, x: np.ndarray, k: int) -> np.ndarray:
        raise NotImplementedError

    def h(self, x: np.ndarray, k: int) -> np.ndarray:
        raise NotImplementedError

    def process_cov(self, k: int) -> np.ndarray:
        """Q_k; time-invariant ``self.Q`` unless overridden."""
        return self.Q

    def measurement_cov(self, k: int) -> np.ndarray:
        """R_k; time-invariant ``self.R`` unless overridden."""
        return self.R

    # --- Jacobians ---------------------------------------------------------------
    def linear_matrices(self):
        """``(F, H, Q, R)`` when the model is linear with constant matrices (every Kalman variant is
        then exact and the innovations' likelihood is known: :mod:`replay.scoring.likelihood`), else None."""
        return None

    def F(self, x: np.ndarray, k: int) -> np.ndarray:
        """Jacobian of f at a single state ``x`` (nx,) -> (nx, nx)."""
        return self._numeric_jacobian(self.f, x, k, self.x_angles)

    def H(self, x: np.ndarray, k: int) -> np.ndarray:
        """Jacobian of h at a single state ``x`` (nx,) -> (nz, nx)."""
        return self._numeric_jacobian(self.h, x, k, self.z_angles)

    def _numeric_jacobian(self, fun, x, k, out_angles):
        n = x.shape[-1]
        eps = self.jacobian_step * np.maximum(1.0, np.abs(x))
        pts = np.concatenate([x + np.diag(eps), x - np.diag(eps)])
        y = fun(pts, k)
        d = residual(y[:n], y[n:], out_angles)
        return (d / (2.0 * eps)[:, None]).T

    # --- compiled kernels (optional) ----------------------------------------------
    def kernels(self):
        """Numba kernels ``(f, h, F, H)`` of one state, or None (the default: no compiled path).

        Each kernel is a ``numba.njit`` function ``(x, p, out)`` writing f(x),
        h(x), the Jacobian of f or the Jacobian of h at one state ``x`` (nx,)
        into ``out``, with ``p`` a float array of the model's parameters at a
        step (:meth:`kernel_params`). They must compute what ``f``, ``h``,
        ``F``, ``H`` compute: a :class:`replay.models.kernel_model.KernelModel`
        derives those from them, so the kernels are its one source. The compiled
        filter paths (:mod:`replay.filters.p002.compiled`) use them; every filter
        also runs without them.
        """
        return None

    def kernel_params(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Parameters ``(p_f, p_h)`` passed to the kernels of :meth:`kernels` at step ``k``."""
        raise NotImplementedError

    # --- sampling and likelihood (particle filters) -------------------------------
    def sample_f(self, x: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        """Draw x_k ~ p(x_k | x_{k-1}) for an array of states."""
        y = self.f(x, k)
        diagonal, factor, _, _ = noise_factor(self.process_cov(k))
        e = rng.standard_normal(y.shape)
        if diagonal:
            e *= factor
        else:
            e = e @ factor.T
        return y + e  # not in place: f may return its input (a random walk)

    def loglik(self, z: np.ndarray, x: np.ndarray, k: int, mask=None) -> np.ndarray:
        """log p(z_k | x_k) for an array of states (Gaussian, wrapped angle residuals).

        ``mask`` selects the measured components (others are missing).
        """
        R = self.measurement_cov(k)
        zh = self.h(x, k)
        angles = self.z_angles
        if mask is not None:
            zh, z, R = zh[..., mask], z[mask], R[np.ix_(mask, mask)]
            angles = remap_indices(self.z_angles, mask)
        diagonal, L, inv_var, logdet = noise_factor(R)
        nz = zh.shape[-1]
        zh2 = np.ascontiguousarray(zh.reshape(-1, nz), dtype=float)
        out = np.empty(len(zh2))
        kernels.gauss_loglik(
            zh2,
            np.ascontiguousarray(z, dtype=float),
            angle_mask(tuple(angles), nz),
            diagonal,
            L if not diagonal else _NO_FACTOR,
            inv_var if diagonal else _NO_VAR,
            logdet + nz * kernels.LOG_2PI,
            out,
        )  # compiled (replay.util.kernels)
        return out.reshape(zh.shape[:-1])

    # --- simulation ----------------------------------------------------------------
    def simulate_measurements(self, x: np.ndarray, rng: np.random.Generator, k0: int = 0) -> np.ndarray:
        """z_k = h(x_k) + v_k for a trajectory ``x`` (n, nx); angles wrapped."""
        n = len(x)
        z = np.empty((n, self.nz))
        for i in range(n):
            L = np.linalg.cholesky(self.measurement_cov(k0 + i))
            z[i] = self.h(x[i], k0 + i) + L @ rng.standard_normal(self.nz)
        if self.z_angles:
            z[:, list(self.z_angles)] = wrap(z[:, list(self.z_angles)])
        return z


class LinearGaussian(Model):
    """x_k = A x_{k-1} + w, z_k = C x_k + v: the case where every Kalman variant is exact."""

    def __init__(self, A, C, Q, R):
        self.A, self.C = np.asarray(A, float), np.asarray(C, float)
        self.Q, self.R = np.asarray(Q, float), np.asarray(R, float)
        self.nx, self.nz = self.A.shape[0], self.C.shape[0]

    def f(self, x, k):
        return x @ self.A.T

    def h(self, x, k):
        return x @ self.C.T

    def F(self, x, k):
        return self.A

    def H(self, x, k):
        return self.C

    def linear_matrices(self):
        return self.A, self.C, self.Q, self.R


def noise_factor(M: np.ndarray):
    """``(diagonal, factor, inverse variances, log det)`` of a covariance matrix, cached.

    ``factor`` is the vector of standard deviations for a diagonal matrix, else
    the lower Cholesky factor. Cached by the matrix's bytes (not its identity),
    so a matrix changed in place is refactored.
    """
    M = np.ascontiguousarray(M, dtype=float)
    return _noise_factor(M.tobytes(), M.shape[0])


@lru_cache(maxsize=128)
def _noise_factor(buf: bytes, n: int):
    M = np.frombuffer(buf).reshape(n, n)
    if is_diagonal(M):
        var = np.diagonal(M).copy()
        if (var <= 0).any():
            raise np.linalg.LinAlgError("covariance has a non-positive diagonal entry")
        return True, np.sqrt(var), 1.0 / var, float(np.log(var).sum())
    L = cholesky(M)
    return False, L, None, float(2.0 * np.log(np.diagonal(L)).sum())


def is_diagonal(M: np.ndarray) -> bool:
    """True when a square matrix has no non-zero off-diagonal entry."""
    return not np.any(M - np.diag(np.diagonal(M)))


def remap_indices(indices, mask) -> tuple[int, ...]:
    """Positions of ``indices`` within the components kept by boolean ``mask``."""
    pos = np.cumsum(mask) - 1
    return tuple(int(pos[i]) for i in indices if mask[i])
