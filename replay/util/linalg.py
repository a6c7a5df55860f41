"""Small dense linear algebra on the hot path of every filter step, for one matrix or a stack.

Every function takes one matrix (n, n) or a stack (M, n, n) (a leading Monte
Carlo run axis) and acts on each matrix alone. For the 3x3 to 20x20 matrices
of a filter step the per-call overhead of ``numpy.linalg`` (about 5 µs) is
most of the cost, so one matrix, or a stack of one, goes straight to LAPACK
(``dpotrf``, ``dgesv`` of SciPy). A stack's Cholesky factors are SciPy's
``dpotrf`` of each matrix too, not numpy's stacked LAPACK: numpy and SciPy
wheels may bundle different OpenBLAS builds, whose factors of the same 11x11
matrix differ in the last bit (numpy 2.4.6 with SciPy 1.17.1), and each matrix of
a stack must get the numbers it gets alone, bit for bit (tests/test_batched.py
asserts it). Results are column-major per matrix, as LAPACK returns one matrix,
whatever M: a matrix product's rounding depends on its operands' memory
layout (BLAS transposition flags), so a stack must have the layout of one.

Failures raise ``numpy.linalg.LinAlgError`` so the run loop can count a
divergence.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dpotrf

from replay.util.errors import ReplayError


def _not_pd(info):
    return np.linalg.LinAlgError(f"matrix not positive definite (LAPACK info {info})")


def _column_major(A):
    """A C-ordered stack laid out column-major per matrix (the layout of LAPACK's output)."""
    return np.ascontiguousarray(A.swapaxes(-1, -2)).swapaxes(-1, -2)


def _potrf(P):
    L, info = dpotrf(P, lower=1, clean=1)
    if info != 0:
        raise _not_pd(info)
    return L


def cholesky(P: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of a symmetric positive-definite matrix (n, n) or stack (M, n, n)."""
    if P.ndim == 2:
        return _potrf(P)
    out = np.empty(P.shape[::-1]).T  # column-major per matrix, as LAPACK returns one
    for m in range(len(P)):  # SciPy's dpotrf on each: numpy's stacked LAPACK may be another build
        out[m] = _potrf(P[m])
    return out


def require_spd(M, name: str) -> np.ndarray:
    """``M`` as a float array, or ReplayError naming ``name`` if not symmetric positive definite."""
    M = np.atleast_2d(np.asarray(M, dtype=float))
    if M.ndim != 2 or M.shape[0] != M.shape[1] or not np.all(np.isfinite(M)):
        raise ReplayError(f"{name} must be a finite square matrix (got shape {M.shape})")
    if not np.allclose(M, M.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(M).max())):
        raise ReplayError(f"{name} must be symmetric")
    try:
        np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        raise ReplayError(
            f"{name} must be positive definite (smallest eigenvalue {np.linalg.eigvalsh(M).min():.3g})"
        ) from None
    return M
