"""``sim/linear``: a linear-Gaussian 3-D position random walk with known noise (for tuning checks).

x_k = x_{k-1} + w_k, w ~ N(0, q I3); z_k = x_k + v_k, v ~ N(0, r I3); x_0 = 0.
The truth is the reference ``position``; the measurements are the sensor
channel ``z``. The true ``q`` and ``r`` are the frame's ``simulation.params``: a filter
tuned on its innovations' likelihood (``replay tune --objective nll``) should
find them (task ``linear``, whose assumed q and r are parameters).
"""

from __future__ import annotations

import numpy as np

from replay.frame import Channel, Frame, Simulation
from replay.util.params import Param

from . import generator

PARAMS = (
    Param("steps", int, 500, "number of samples", low=1),
    Param("q", float, 0.3, "true process noise variance per axis and step", unit="m^2", low=0, low_open=True),
    Param("r", float, 2.0, "true measurement noise variance per axis", unit="m^2", low=0, low_open=True),
)


@generator(PARAMS)
def make_frame(rng: np.random.Generator, *, steps, q, r) -> Frame:
    """Simulate ``steps`` samples of the walk from ``rng``."""
    x = np.cumsum(rng.standard_normal((steps, 3)) * np.sqrt(q), axis=0)
    z = x + rng.standard_normal((steps, 3)) * np.sqrt(r)
    t = np.arange(1, steps + 1, dtype=float)
    ref = {"position": Channel(x, "m", "enu", components=("x", "y", "z"), description="true position")}
    meas = Channel(z, "m", "enu", components=("x", "y", "z"), description="position + N(0, r I3)")
    meta = {"source": "synthetic: replay.sim.linear", "synthetic": True, "crs": None}
    return Frame(t, {"z": meas}, ref, None, meta, simulation=Simulation(dt=1.0))
