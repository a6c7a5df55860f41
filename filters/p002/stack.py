"""Stacked small-matrix helpers of the paper-002 numpy engine (:mod:`replay.filters.p002.stcpf`).

Every function acts on stacks (leading axes: runs, particles, points) at once:

* :func:`batched_cholesky` — Cholesky factors, a non-positive-definite matrix
  repaired by flooring its eigenvalues (as :func:`replay.filters.p002.compiled_util.factor`);
* :func:`solve_stack` — S^-1 B for small symmetric positive-definite S;
* :func:`circular_mean` — equal-weight mean over the cubature points (circular
  for angle components);
* :func:`wrap_inplace`, :func:`fast_residual` — :func:`replay.util.angles.wrap`
  and :func:`replay.util.angles.residual` bit for bit, without temporaries.
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import TWO_PI, index


def batched_cholesky(P):
    """Lower Cholesky factors of a stack of covariances; a non-positive-definite
    one is repaired by clipping its eigenvalues. Returns (L, repairs per leading index)."""
    try:
        return np.linalg.cholesky(P), None
    except np.linalg.LinAlgError:
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        s, U = np.linalg.eigh(P)
        floor = 1e-12 * np.maximum(1.0, s.max(axis=-1, keepdims=True))
        bad = s.min(axis=-1) <= floor[..., 0]
        P = (U * np.maximum(s, floor)[..., None, :]) @ np.swapaxes(U, -1, -2)
        return np.linalg.cholesky(P), bad


def solve_stack(S, B):
    """S^-1 B for a stack of small symmetric positive-definite S (..., m, m), B (..., m, p).

    m <= 3: the explicit inverse (adjugate / determinant), a few array
    operations for the whole stack instead of one LAPACK call per matrix; a
    singular S gives non-finite values (the run is then counted as diverged).
    Larger m: ``numpy.linalg.solve``.
    """
    m = S.shape[-1]
    if m > 3:
        return np.linalg.solve(S, B)
    with np.errstate(divide="ignore", invalid="ignore"):
        if m == 1:
            return B / S
        if m == 2:
            a, b, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
            inv = np.stack([np.stack([d, -b], -1), np.stack([-b, a], -1)], -2)
            return inv @ B / (a * d - b * b)[..., None, None]
        a, b, c = S[..., 0, 0], S[..., 0, 1], S[..., 0, 2]
        e, f, i = S[..., 1, 1], S[..., 1, 2], S[..., 2, 2]
        inv = np.empty_like(S)
        inv[..., 0, 0] = e * i - f * f
        inv[..., 0, 1] = inv[..., 1, 0] = c * f - b * i
        inv[..., 0, 2] = inv[..., 2, 0] = b * f - c * e
        inv[..., 1, 1] = a * i - c * c
        inv[..., 1, 2] = inv[..., 2, 1] = b * c - a * f
        inv[..., 2, 2] = a * e - b * b
        det = a * inv[..., 0, 0] + b * inv[..., 1, 0] + c * inv[..., 2, 0]
        return inv @ B / det[..., None, None]


def circular_mean(Y, angles):
    """Equal-weight mean over the points axis -2 (circular for the ``angles`` components)."""
    mean = np.einsum("...ci->...i", Y) * (1.0 / Y.shape[-2])
    if angles:
        i = index(tuple(angles))
        a = Y[..., i]
        mean[..., i] = np.arctan2(np.einsum("...ci->...i", np.sin(a)), np.einsum("...ci->...i", np.cos(a)))
    return mean


def wrap_inplace(x, angles):
    """Wrap the ``angles`` components of ``x`` in place: the arithmetic of
    :func:`replay.util.angles.wrap` (bit for bit) without its temporaries. Returns ``x``."""
    if angles:
        a = x[..., index(tuple(angles))]
        t = a * (1.0 / TWO_PI)
        t += 0.5
        np.floor(t, out=t)
        t *= TWO_PI
        a -= t
        if not isinstance(index(tuple(angles)), slice):  # fancy index: a is a copy
            x[..., index(tuple(angles))] = a
    return x


def fast_residual(a, b, angles):
    """``a - b`` with the ``angles`` components wrapped; equals :func:`replay.util.angles.residual`."""
    return wrap_inplace(np.subtract(a, b), angles)
