"""Small dense linear algebra on the hot path of every filter step.

Direct LAPACK calls: for the 3x3 to 20x20 matrices of a filter step the
per-call overhead of ``numpy.linalg`` (several microseconds) is most of the
cost. Failures raise ``numpy.linalg.LinAlgError`` so the run loop can count a
divergence.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dposv, dpotrf


def cholesky(P: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of a symmetric positive-definite matrix."""
    L, info = dpotrf(P, lower=1, clean=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"matrix not positive definite (LAPACK info {info})")
    return L


def solve_spd(S: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``S^-1 B`` for symmetric positive-definite ``S``."""
    _, X, info = dposv(S, B, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"matrix not positive definite (LAPACK info {info})")
    return X


def gain(S: np.ndarray, Pxz: np.ndarray) -> np.ndarray:
    """Kalman gain ``K = Pxz S^-1`` (S symmetric positive definite)."""
    return solve_spd(S, Pxz.T).T
