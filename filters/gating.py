"""Outlier gating: a per-sensor rejection threshold, as robot_localization's ``*_rejection_threshold``.

A model may carry :class:`Gates` (``model.gates``; the fusion task makes them from the
mapping's ``rejection_threshold``): the measurement components in groups (one group per
sensor field, e.g. a GPS fix's east and north), each with a Mahalanobis threshold ``d``.
At every update, each group present is tested alone:

* **Kalman family** (EKF, UKF, CKF): the innovation ``y_g`` and its covariance ``S_gg`` (the
  block of ``S = H P H' + R``, or ``Pzz + R``); when ``y_g' S_gg^-1 y_g > d^2`` the group is
  rejected: its innovation and its columns of the cross-covariance (``P H'``, ``Pxz``) are
  zeroed and its cross terms in S removed, so that the gain's columns of the group vanish and
  the update is, number for number, the update without it. The test is :func:`gate`, called
  inside the one compiled update (:func:`replay.filters.kalman_kernels.joseph_update_into`,
  :func:`~replay.filters.kalman_kernels.kalman_correct_into`): the step-by-step engines and
  the per-run functions run the same kernel (its ``py_func`` is the readable reference).
* **Particle filters** (``pf`` and the filters on its engine): the likelihood of the group
  under the particles' predictive density, moment-matched (:func:`particle_rejects`):
  ``zh = sum w_i h(x_i)``, ``S = sum w_i (h(x_i) - zh)(h(x_i) - zh)' + R_gg`` with the weights
  before the update; the group is left out of the likelihood when ``(z - zh)' S^-1 (z - zh) >
  d^2``, i.e. when its predictive (Gaussian) likelihood is below that of a ``d``-sigma
  deviation. A rule on the spread of the cloud, not on its best particle: an impoverished
  cloud does not reject every measurement.

Rejections are counted per run and group (``info["rejected"]``: group name -> count) and the
rejected components leave the NIS and its degrees of freedom. A filter whose engine does not
gate is refused on a gated model (:func:`check`), never run ungated in silence. The kernels take a
gated update's arrays as one :data:`Gate`; without gates, None (that branch compiled away: no cost).
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass

import numba as nb
import numpy as np

from replay.util.angles import residual
from replay.util.errors import ReplayError
from replay.util import kernel_cache  # noqa: F401  numba's cache of replay's kernels: locked, sealed
from replay.util.kernels import cholesky, whitened_norm2

Gate = namedtuple("Gate", "group limit2 rej cut")  # a gated update's arrays (:meth:`Tally.args`)

NO_GROUP = -1


@dataclass(frozen=True)
class Gates:
    """Measurement components in groups with a threshold each: ``group`` (nz,) the group of each
    component (``NO_GROUP``: never tested), ``limit`` (G,) the Mahalanobis thresholds d (inf: no
    test), ``names`` (G,) the groups' names (the counts' keys)."""

    group: np.ndarray
    limit: np.ndarray
    names: tuple

    @property
    def limit2(self) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(self.limit, float) ** 2)


def active(model) -> Gates | None:
    """The model's gates when any group has a finite threshold, else None."""
    g = getattr(model, "gates", None)
    return g if g is not None and np.isfinite(np.asarray(g.limit, float)).any() else None


def check(flt, engine, model) -> None:
    """Refuse (one line) a filter whose engine does not gate, on a model with gates."""
    g = active(model)
    if g is not None and not getattr(engine, "GATES", False):
        raise ReplayError(
            f"filter {flt.name}: the task gates its measurements (rejection_threshold of "
            f"{', '.join(n for n, d in zip(g.names, g.limit) if np.isfinite(d))}) and this filter "
            "does not implement gating: run ekf, ukf, ckf or pf, or remove the rejection_threshold"
        )


class Tally:
    """Per run: the rejections of each group, and the components cut at the last update."""

    def __init__(self, model, M: int):
        self.gates = active(model)
        G = len(self.gates.names) if self.gates is not None else 0
        self.count = np.zeros((M, G), np.int64)
        self.ids = np.arange(M)

    def keep(self, ok):
        self.ids = self.ids[ok]

    def args(self, mask, n: int):
        """The :data:`Gate` (group, limit2, rej, cut) of a gated update of ``n`` runs with the components ``mask``."""
        group = np.asarray(self.gates.group, np.int64)
        group = np.ascontiguousarray(group if mask is None else group[mask])
        return Gate(group, self.gates.limit2, np.zeros((n, len(self.gates.names)), np.int64), np.zeros(n, np.int64))

    def add(self, rej, rows=None):
        """Add an update's rejections ``rej`` (n, G) of the active runs ``rows`` (None: all)."""
        if rej.shape[1]:
            self.count[self.ids if rows is None else self.ids[rows]] += rej

    def info(self, m: int, info: dict) -> None:
        if self.gates is not None:
            info["rejected"] = {
                name: int(c)
                for name, c, d in zip(self.gates.names, self.count[m], self.gates.limit)
                if np.isfinite(d)  # the gated inputs only
            }


@nb.njit(cache=True)
def gate(y, S, B, group, limit2, rej):
    """Test each group g of components (``group[q] == g``, ``limit2[g]`` finite) of one run:
    NIS_g = y_g' S_gg^-1 y_g; above ``limit2[g]`` the group is rejected (module docstring): y_g = 0,
    B's columns of g (B = P H' or Pxz) = 0, S's cross terms between g and the others = 0, and
    ``rej[g] += 1``. A group whose S_gg has no Cholesky factor is kept (the update refuses it).
    Returns the number of components rejected."""
    nz = y.shape[0]
    cut = 0
    for g in range(limit2.shape[0]):
        if not limit2[g] < np.inf:
            continue
        ng = 0
        for q in range(nz):
            if group[q] == g:
                ng += 1
        if ng == 0:
            continue
        Sg, yg, L = np.empty((ng, ng)), np.empty(ng), np.empty((ng, ng))
        a = 0
        for q in range(nz):
            if group[q] != g:
                continue
            yg[a] = y[q]
            b = 0
            for r in range(nz):
                if group[r] == g:
                    Sg[a, b] = S[q, r]
                    b += 1
            a += 1
        if not cholesky(Sg, L) or whitened_norm2(L, yg) <= limit2[g]:
            continue
        rej[g] += 1
        for q in range(nz):
            if group[q] != g:
                continue
            cut += 1
            y[q] = 0.0
            for i in range(B.shape[0]):
                B[i, q] = 0.0
            for r in range(nz):
                if group[r] != g:
                    S[q, r] = 0.0
                    S[r, q] = 0.0
    return cut


def particle_rejects(gates: Gates, model, X, w, z, k, present, extra=None) -> np.ndarray:
    """The components of one run's measurement ``z`` (nz,) rejected by the particle rule (module
    docstring), as a mask (nz,) (``present``: the components measured), and the groups rejected.
    ``extra`` (nz,): variances added to S (the process noise of the measured components when ``X``
    are the predicted particles f(x^i) before it is drawn: the PF's optimal proposal)."""
    group, limit2 = np.asarray(gates.group), gates.limit2
    cut, hit = np.zeros(len(z), bool), []
    Zp = None
    for g in range(len(limit2)):
        sel = present & (group == g)
        if not np.isfinite(limit2[g]) or not sel.any():
            continue
        if Zp is None:
            Zp = np.asarray(model.h(X, k), float)
        idx = np.flatnonzero(sel)
        angles = tuple(i for i, j in enumerate(idx) if j in model.z_angles)
        H = Zp[:, idx]
        zh = H.T @ w
        for i in angles:  # circular mean
            zh[i] = np.arctan2(w @ np.sin(H[:, i]), w @ np.cos(H[:, i]))
        D = residual(H, zh, angles)
        S = (D * w[:, None]).T @ D + np.asarray(model.measurement_cov(k), float)[np.ix_(idx, idx)]
        if extra is not None:
            S[np.diag_indices(len(idx))] += extra[idx]
        y = residual(z[idx], zh, angles)
        if float(y @ np.linalg.solve(S, y)) > limit2[g]:
            cut[idx] = True
            hit.append(g)
    return cut, hit


def per_filter(results) -> dict:
    """Per filter result (``name``, ``records``: replay's evaluation): each gated input's
    rejections per run (``record.rejected``), where a gate exists."""
    out = {}
    for r in results:
        recs = [rec.rejected for rec in sorted(r.records, key=lambda d: d.run) if rec.rejected is not None]
        if recs:
            out[r.name] = {k: [int(d.get(k, 0)) for d in recs] for k in recs[0]}
    return out
