"""``sim/ungm``: the univariate nonstationary growth model of paper 002, §3.2 (benchmark 1).

x_0 = 0; 100 steps; Gaussian noise, Q = R = 1 (first set) or Q = R = 10
(second set): pass ``q`` and ``r``. The truth is the reference channel
``state`` (and ``position``, one component, for the scorer); the measurement
z_k = x_k^2 / 20 + v_k is the sensor channel ``z``.
"""

from __future__ import annotations

import numpy as np

from replay.frame import Channel, Frame, Simulation
from replay.models.ungm import UNGM
from replay.util.params import Param

from . import generator

PARAMS = (
    Param("steps", int, 100, "number of samples (k = 1..steps)", low=1),
    Param("q", float, 1.0, "process noise variance Q (002 §3.2: 1 or 10)", low=0, low_open=True),
    Param("r", float, 1.0, "measurement noise variance R (002 §3.2: 1 or 10)", low=0, low_open=True),
    Param("x0", float, 0.0, "initial state x_0"),
    Param("growth", float, 2.5, "coefficient g of the term g x / (1 + x^2) (see replay.models.ungm)"),
)


@generator(PARAMS)
def make_frame(rng: np.random.Generator, *, steps, q, r, x0, growth) -> Frame:
    """Simulate ``steps`` samples (k = 1..steps) of the UNGM from ``rng``."""
    model = UNGM(q, r, growth)
    w = rng.standard_normal(steps) * np.sqrt(q)
    v = rng.standard_normal(steps) * np.sqrt(r)
    x = np.empty(steps)
    prev = np.array([float(x0)])
    for k in range(steps):
        prev = model.f(prev, k) + w[k]
        x[k] = prev[0]
    z = x * x / 20.0 + v
    t = np.arange(1, steps + 1, dtype=float)
    ref = {
        "position": Channel(
            x[:, None], "1", "state", components=("x",), description="UNGM state (scored as the 1-D 'position')"
        )
    }
    meas = Channel(z[:, None], "1", "measurement", components=("z",), description="z = x^2/20 + v")
    meta = {"source": "synthetic: replay.sim.ungm", "synthetic": True, "crs": None}
    return Frame(t, {"z": meas}, ref, None, meta, simulation=Simulation(dt=1.0, initial_state=(x0,), state=("x",)))
