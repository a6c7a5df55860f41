"""``measurements``: the raw observations as an estimate — the baseline every filter must beat.

Where the model observes a state component directly (a row of ``H`` with one non-zero
entry, ±1, and a linear ``h``: GPS fixes, the synthetic positions of the ``position``
task, a depth sensor), the estimate of that component is its latest measurement
(``x_i = z_j / H_ji``, held until the next one) and its variance the measurement's
(``R_jj``); a component never measured keeps the prior. No model, no smoothing: what a
user would get by plotting the sensor. Scored by the same scorer, the row says whether a
filter is worse than the input it reads (the table flags such rows).

Deterministic: it draws no random number. A model with no direct observation (range and
bearing, a sonar) has nothing to show: :func:`direct_rows` is empty and the pipeline adds
no such row.
"""

from __future__ import annotations

import numpy as np

from replay.filters.case import Case
from .base import Filter


def direct_rows(model, x0) -> list[tuple[int, int, float]]:
    """``(measurement row j, state component i, coefficient)`` of the rows of ``H(x0)`` that
    observe one component directly (one non-zero entry of magnitude 1, and ``h`` linear
    there: ``h(x0 + e_i) - h(x0) = H_ji``)."""
    x0 = np.asarray(x0, float)
    H = np.atleast_2d(np.asarray(model.H(x0, 0), float))
    out = []
    h0 = np.asarray(model.h(x0[None], 0), float)[0]
    for j, row in enumerate(H):
        nz = np.flatnonzero(row)
        if len(nz) != 1 or abs(abs(row[nz[0]]) - 1.0) > 1e-12:
            continue
        i = int(nz[0])
        step = np.zeros_like(x0)
        step[i] = 1.0
        if abs(np.asarray(model.h((x0 + step)[None], 0), float)[0][j] - h0[j] - row[i]) < 1e-9:
            out.append((j, i, float(row[i])))
    return out


class MeasurementsEngine:
    GATES = True  # the raw observations, every one: a gate does not apply (replay.filters.gating)

    def __init__(self, model, rngs):
        self.model = model

    def start(self, X0, P0):
        self.x, self.P = np.array(X0, float), np.array(P0, float)
        self.rows = direct_rows(self.model, X0[0])

    def keep(self, ok):
        self.x, self.P = self.x[ok], self.P[ok]

    def step(self, k, Z, finite):
        R = np.asarray(self.model.measurement_cov(k), float)
        for j, i, c in self.rows:
            got = finite[:, j]
            self.x[got, i] = Z[got, j] / c
            self.P[got, i, :] = 0.0
            self.P[got, :, i] = 0.0
            self.P[got, i, i] = R[j, j]
        n = len(self.x)
        return self.x.copy(), self.P.copy(), np.full(n, np.nan), np.zeros(n, int)

    def finish(self, m, info):
        info["measured_components"] = sorted({i for _, i, _ in self.rows})


class Measurements(Filter):
    """The latest direct observation of each state component (module docstring)."""

    name = "measurements"
    CASE = Case("sim/lake-depth", "depth", first=60)
    PARAMS = ()

    def engine(self, model, rngs):
        return MeasurementsEngine(model, rngs)
