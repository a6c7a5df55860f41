"""Models written once: numba kernels of one state, array methods derived from them.

A model's equations live in one place, a kernels module of four module-level
``numba.njit(cache=True)`` functions of one state (the :meth:`Model.kernels`
protocol)::

    f(x, p_f, out)   out[:]    = f(x)        x (nx,), out (nx,)
    h(x, p_h, out)   out[:]    = h(x)        out (nz,)
    F(x, p_f, J)     J[:, :]   = df/dx (x)   J (nx, nx)
    H(x, p_h, J)     J[:, :]   = dh/dx (x)   J (nz, nx)

with ``(p_f, p_h) = model.kernel_params(k)``, float arrays of the model's
parameters at step ``k``. A kernel writes every entry of its output (which
starts uninitialised) and reads no more of ``x`` than its nx entries (they are
not bounds-checked). The compiled filters (:func:`replay.filters.compiled.bind`)
call the kernels as they are; :class:`KernelModel` derives from them the array
methods ``f``, ``h``, ``F``, ``H`` of the model protocol on states ``(..., nx)``
(one state (nx,), or any stack of them): a stack through the kernel's
``numba.guvectorize`` form over the leading axes (:func:`array_form`), one
state through the kernel itself. No second copy of the equations in numpy.

Compilation: the four array forms of a model class are built on the first call
of one of its array methods (not at import), compiled once per machine and
cached on disk by numba (``__pycache__`` beside the kernels module, checked
against the module's source): a later process loads them in milliseconds,
after numba's own start-up (about 0.2 s to import, 0.2 s for its first load).
"""

from __future__ import annotations

import importlib
from functools import lru_cache

import numpy as np

from replay.model import Model

# One layout per output rank, the output passed in (written in place) so that its core
# dimension m may be one no input has (nz, or nx for f). Not one layout per role: numba
# caches a gufunc's loop wrapper under (function, signature) only, not the layout, so a
# kernel serving as both f and h (an identity) must be compiled with one layout.
_VECTOR = ("void(f8[:], f8[:], f8[:])", "(n),(p),(m)")
_MATRIX = ("void(f8[:], f8[:], f8[:, :])", "(n),(p),(m,n)")


@lru_cache(maxsize=None)
def array_form(kernel, matrix: bool):
    """The gufunc ``g(x, p, out)`` applying the one-state numba ``kernel`` over the leading axes
    of ``x`` (..., n) and ``out`` (..., m) (or (..., m, n) when ``matrix``); ``p`` is shared."""
    # lazy: start-up, the model protocol imports this module: numba measured ~800 ms, only to compile
    import numba as nb  # noqa: PLC0415
    from replay.util import kernel_cache  # noqa: PLC0415, F401  numba's cache of replay's kernels: locked, sealed

    if not hasattr(kernel, "py_func"):  # NUMBA_DISABLE_JIT=1: the plain-Python kernel, state by state
        return _Loop(kernel)
    sig, layout = _MATRIX if matrix else _VECTOR
    return nb.guvectorize([sig], layout, writable_args=(2,), cache=True)(kernel.py_func)


class _Loop:
    """The array form of a kernel when numba's JIT is disabled: the same Python function over
    the leading axes (plain Python must always run; the numbers are the kernel's)."""

    def __init__(self, kernel):
        self.kernel = kernel

    def ufunc(self, x, p, out):
        for idx in np.ndindex(x.shape[:-1]):
            self.kernel(x[idx], p[idx] if p.ndim > 1 else p, out[idx])  # p per state (at_steps) or shared


_forms: dict = {}  # model class -> array forms of its kernels (f, h, F, H)


class KernelModel(Model):
    """A model declared by its kernels (module docstring): ``f``, ``h``, ``F``, ``H`` derived.

    Subclasses name the module of their kernels in ``kernel_module`` (module-level
    functions ``f``, ``h``, ``F``, ``H``) and define :meth:`kernel_params`. The
    array methods take states (..., nx) and return (..., nx), (..., nz),
    (..., nx, nx), (..., nz, nx) as float64 arrays of their own (never a view of ``x``).
    """

    kernel_module: str
    vector_jacobians = True  # F and H take stacks of states (..., nx) too

    def kernels(self):
        return _module_kernels(self.kernel_module)

    def _forms(self):
        """``(kernels, array forms)`` of this model's class, built on first use."""
        forms = _forms.get(type(self))
        if forms is None:
            f, h, F, H = kernels = _module_kernels(self.kernel_module)  # not self.kernels(): a subclass
            # may hide its kernels from the filters and still compute with them
            forms = _forms[type(self)] = (
                kernels,
                tuple(array_form(k, m).ufunc for k, m in ((f, False), (h, False), (F, True), (H, True))),
            )
        return forms

    def _apply(self, i, x, p, shape):
        """Kernel ``i`` (0-3: f, h, F, H) at the states ``x`` into a new array of ``shape``:
        the kernel itself for one state (a gufunc call costs about 1 us more), else its array form."""
        out = np.empty(shape)
        kernels, arrays = self._forms()
        (kernels if x.ndim == 1 else arrays)[i](x, p, out)
        return out

    def _states(self, x):
        x = np.asarray(x, dtype=float)
        if x.ndim == 0 or x.shape[-1] != self.nx:  # the kernels index x unchecked
            raise ValueError(f"states of {type(self).__name__} are (..., {self.nx}), not {x.shape}")
        return x

    def f(self, x, k):
        x = self._states(x)
        return self._apply(0, x, self.kernel_params(k)[0], x.shape)

    def h(self, x, k):
        x = self._states(x)
        return self._apply(1, x, self.kernel_params(k)[1], x.shape[:-1] + (self.nz,))

    def F(self, x, k):
        """Jacobian of f at ``x`` (nx,) -> (nx, nx), or at a stack (..., nx) -> (..., nx, nx)."""
        x = self._states(x)
        return self._apply(2, x, self.kernel_params(k)[0], x.shape + (self.nx,))

    def H(self, x, k):
        """Jacobian of h at ``x`` (nx,) -> (nz, nx), or at a stack (..., nx) -> (..., nz, nx)."""
        x = self._states(x)
        return self._apply(3, x, self.kernel_params(k)[1], x.shape[:-1] + (self.nz, self.nx))

    def step_params(self, steps) -> tuple[np.ndarray, np.ndarray]:
        """The kernel parameters ``(p_f, p_h)`` of the steps ``steps``, stacked (for :meth:`at_steps`)."""
        pairs = [self.kernel_params(int(k)) for k in steps]
        return np.stack([a for a, _ in pairs]), np.stack([b for _, b in pairs])

    def at_steps(self, name: str, x, params):
        """``name`` (``"f"``, ``"h"``, ``"F"`` or ``"H"``) of the state ``x[i]`` at step ``i`` of
        ``params`` (:meth:`step_params` of the steps), for a stack ``x`` (m, nx), in one call of the
        array form (a smoother linearising every step at once)."""
        i = "fhFH".index(name)
        x = self._states(x)
        p = params[i % 2]
        rows = (self.nx, self.nz)[i % 2]
        out = np.empty(x.shape[:1] + ((rows,) if i < 2 else (rows, self.nx)))
        self._forms()[1][i](x, p, out)
        return out


def _module_kernels(name: str):
    """The module-level kernels ``f, h, F, H`` of the kernels module ``name``."""
    mod = importlib.import_module(name)
    return mod.f, mod.h, mod.F, mod.H
