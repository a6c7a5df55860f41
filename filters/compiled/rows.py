"""Rows forms of one model's kernels for the whole-run loops: a template, bound to a model by
:func:`replay.filters.compiled.row_kernels` (the mechanism: :mod:`replay.filters.compiled.copies`).

    f_rows(X (P, nx), p, out (P, nx))      out[i] = f(X[i], p)
    h_rows(X (P, nx), p, out (P, nz))      out[i] = h(X[i], p)
    F_rows(X (P, nx), p, J (P, nx, nx))    J[i] = F(X[i], p)
    H_rows(X (P, nx), p, J (P, nz, nx))    J[i] = H(X[i], p)

In the bound copy the model's one-state kernels are module globals, so numba
inlines them into these loops: a run loop makes one call through a function
pointer per stack of states (the particles of a run, the sigma points of a
run), not one per state. The arithmetic of each state is the kernel's own.
"""

import numba as nb
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed

# MODEL KERNELS: replay.filters.compiled.bind puts here the import of one model's f, h, F, H


@nb.njit(cache=True)
def f_rows(X, p, out):
    for i in range(X.shape[0]):
        f(X[i], p, out[i])  # noqa: F821  (the bound copy's import)


@nb.njit(cache=True)
def h_rows(X, p, out):
    for i in range(X.shape[0]):
        h(X[i], p, out[i])  # noqa: F821


@nb.njit(cache=True)
def F_rows(X, p, J):
    for i in range(X.shape[0]):
        F(X[i], p, J[i])  # noqa: F821


@nb.njit(cache=True)
def H_rows(X, p, J):
    for i in range(X.shape[0]):
        H(X[i], p, J[i])  # noqa: F821
