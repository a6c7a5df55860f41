"""The measurement kernels of the fusion task's kinematic models: signed selections.

``p_h = [n, i_0 .. i_{n-1}, s_0 .. s_{n-1}]``: measurement j is ``s_j * x[i_j]`` (depth is
``-up``), so ``H`` has one entry ``s_j`` per row. Shared by :mod:`kinematic2_kernels` and
:mod:`kinematic3_kernels` (see :mod:`replay.models.kernel_model`).
"""

from __future__ import annotations

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed


@nb.njit(cache=True)
def h(x, p, out):
    """out[j] = s_j x[i_j]."""
    n = int(p[0])
    for j in range(n):
        out[j] = p[1 + n + j] * x[int(p[1 + j])]


@nb.njit(cache=True)
def H(x, p, J):
    """J[j, i_j] = s_j, 0 elsewhere."""
    n = int(p[0])
    for j in range(J.shape[0]):
        for i in range(J.shape[1]):
            J[j, i] = 0.0
    for j in range(n):
        J[j, int(p[1 + j])] = p[1 + n + j]
