"""Covariances as named table columns, and back.

A per-step table (``estimates/<filter>.csv.gz``, a campaign unit's Parquet table) holds the
variances as ``P{i}{i}`` (one column per state component, the first layout) and the
covariances of components ``i < j`` as ``P{i}_{j}``. The estimates file keeps the
covariances among the position components, the campaign store those of the whole state.
A table written before the covariances were kept has the variances only: :func:`matrices`
then returns diagonal matrices and says so.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np


def variance_names(nx: int) -> list[str]:
    return [f"P{i}{i}" for i in range(nx)]


def covariance_names(index) -> list[str]:
    """The names of the covariances among state components ``index`` (pairs in increasing order)."""
    return [f"P{i}_{j}" for i, j in combinations(sorted(int(k) for k in index), 2)]


def covariance_columns(P, index) -> dict[str, np.ndarray]:
    """``{P{i}_{j}: P[:, i, j]}`` for the pairs of ``index`` (``P``: (n, nx, nx))."""
    return {f"P{i}_{j}": P[:, i, j] for i, j in combinations(sorted(int(k) for k in index), 2)}


def matrices(columns, nx: int, n: int | None = None) -> tuple[np.ndarray, bool]:
    """((n, nx, nx) covariances, whether any covariance column was present) from ``columns``
    (a mapping name -> array): the variances ``P{i}{i}``, and ``P{i}_{j}`` where present
    (symmetric; absent pairs are 0)."""
    diag = np.column_stack([np.asarray(columns[f"P{i}{i}"], float) for i in range(nx)]) if nx else np.zeros((n or 0, 0))
    out = np.zeros((len(diag), nx, nx))
    out[:, np.arange(nx), np.arange(nx)] = diag
    full = False
    for i, j in combinations(range(nx), 2):
        col = columns.get(f"P{i}_{j}")
        if col is not None:
            out[:, i, j] = out[:, j, i] = np.asarray(col, float)
            full = True
    return out, full


def as_matrices(P) -> np.ndarray:
    """(n, nx, nx) covariances from covariances as they are, or from variances (n, nx)."""
    P = np.asarray(P, float)
    if P.ndim == 3:
        return P
    out = np.zeros(P.shape + P.shape[-1:])
    out[:, np.arange(P.shape[1]), np.arange(P.shape[1])] = P
    return out
