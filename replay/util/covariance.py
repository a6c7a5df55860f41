"""Declared covariance parameters: a symmetric positive-definite matrix, its diagonal (tasks'
and simulators' Q, R, P0) or, for a filter's own noise settings, a scalar times the identity.

Kept in :mod:`replay.util` (no project import) so that tasks, simulators and filters declare
covariances alike (:mod:`replay.models.noise` re-exports them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from replay.util.params import Param, _is_number


@dataclass(frozen=True)
class Covariance(Param):
    """A declared covariance parameter (``type=list``): a symmetric positive-definite
    ``dim`` x ``dim`` matrix (nested lists), or its diagonal (``dim`` positive numbers).

    Checked values are normalised: a diagonal matrix to its diagonal (a tuple),
    any other to a tuple of row tuples, so that equal matrices compare equal.
    :func:`as_matrix` turns either form into an array.
    """

    dim: int | None = None

    def accepts(self) -> str:
        n = f"{self.dim}x{self.dim}" if self.dim else "square"
        diag = f"{self.dim} positive numbers" if self.dim else "positive numbers"
        article = "an" if n.startswith(("8", "11", "18")) else "a"
        return f"{article} {n} symmetric positive-definite matrix or its diagonal ({diag})" + (
            " (or null)" if self.optional else ""
        )

    def check(self, value, owner: str = ""):
        return super().check(value.tolist() if isinstance(value, np.ndarray) else value, owner)

    def _coerce(self, v):
        if not isinstance(v, (list, tuple)) or not v:
            return False, v
        rows = v if all(isinstance(r, (list, tuple)) for r in v) else None
        leaves = [x for r in rows for x in r] if rows is not None else list(v)
        if not all(_is_number(x) and math.isfinite(x) for x in leaves):
            return False, v
        if rows is None:
            ok = (self.dim is None or len(v) == self.dim) and all(x > 0 for x in v)
            return ok, tuple(float(x) for x in v)
        n = len(rows)
        if any(len(r) != n for r in rows) or (self.dim is not None and n != self.dim):
            return False, v
        M = np.array(rows, float)
        if not np.allclose(M, M.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(M).max())):
            return False, v
        try:
            np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            return False, v
        if not np.any(M - np.diag(np.diagonal(M))):
            return True, tuple(float(x) for x in np.diagonal(M))
        return True, tuple(tuple(float(x) for x in r) for r in M)


def diagonal(M) -> tuple:
    """The diagonal of a matrix as a tuple of floats (a :class:`Covariance` default)."""
    return tuple(float(x) for x in np.diagonal(np.asarray(M, float)))


def as_matrix(value) -> np.ndarray | None:
    """A checked :class:`Covariance` value as a float array (a diagonal given as numbers -> diag)."""
    if value is None:
        return None
    M = np.asarray(value, float)
    return np.diag(M) if M.ndim == 1 else M
