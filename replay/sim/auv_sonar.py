"""``sim/auv-sonar``: the simulated AUV of paper 002, benchmark 2 (Table 2).

A seeded generator of a frame: the true state trajectory as reference
channels and the sonar's range/elevation/azimuth as a sensor channel. The
truth follows :class:`replay.models.auv_sonar.AUVSonar` with process noise Q;
the sonar noise is Gaussian with covariance R, or the paper's mixed Gaussian
(1 - eps) N(0, R) + eps N(0, scale R) (Table 6: eps = 0.05, scale = 10).

The first sample is at t = T: the AUV starts at the sonar (range 0, bearing
undefined), so the initial state x0 at t = 0 is metadata, not a measurement.

Geometry (measured in docs/reproduction/002.md): with Table 2's Q the speed,
pitch and yaw are random walks (pitch standard deviation 1 rad after 100 s)
and the truth dives about 700 m in 100 s (v = 10 m/s at pitch pi/4), outside
the paper's PSO box z in [-300, 0]. ``truth_noise=false`` gives the noiseless
trajectory (the same draws are made, so the sonar noise of a run is unchanged;
the filters still assume the task's Q); ``x0`` and ``steps`` change the pitch
and the horizon.
"""

from __future__ import annotations

import numpy as np

from replay.util.angles import wrap
from replay.util.params import Param
from replay.frame import Channel, Frame, Simulation
from replay.models.auv_sonar import AUVSonar, Q_TABLE2, R_TABLE2
from replay.models.noise import Covariance, as_matrix, diagonal

from . import Numbers, generator

X0_TABLE2 = (0.0, 0.0, 0.0, 10.0, np.pi / 4, np.pi / 10)
STATE = ("x", "y", "z", "v", "pitch", "yaw")  # the model's state (replay.models.auv_sonar)

PARAMS = (
    Param("steps", int, 100, "number of samples (t = T, 2T, ..., steps T)", low=1),
    Param("T", float, 1.0, "time step", unit="s", low=0, low_open=True),
    Numbers(
        "x0", list, X0_TABLE2, "initial state [x, y, z, v, pitch, yaw] at t = 0 (Table 2)", unit="m, m/s, rad", length=6
    ),
    Param("yaw_rate", float, 0.25, "constant yaw rate of the AUV", unit="rad/s"),
    Covariance("Q", list, diagonal(Q_TABLE2), "process noise covariance (Table 2)", dim=6),
    Covariance(
        "R",
        list,
        diagonal(R_TABLE2),
        "sonar noise covariance, range/elevation/azimuth (Table 2)",
        unit="m^2, rad^2",
        dim=3,
    ),
    Param(
        "mixture_eps",
        float,
        0.0,
        "probability of an outlier, drawn from N(0, mixture_scale R) (Table 6: 0.05)",
        low=0,
        high=1,
    ),
    Param("mixture_scale", float, 10.0, "outlier covariance as a multiple of R (Table 6: 10)", low=0, low_open=True),
    Param(
        "truth_noise",
        bool,
        True,
        "apply the process noise Q to the true trajectory (false: the "
        "noiseless trajectory from x0; the sonar noise draws are unchanged)",
    ),
)


@generator(PARAMS)
def make_frame(
    rng: np.random.Generator, *, steps, T, x0, yaw_rate, Q, R, mixture_eps, mixture_scale, truth_noise
) -> Frame:
    """Simulate ``steps`` samples of truth and sonar measurements from ``rng``."""
    model = AUVSonar(Q=as_matrix(Q), R=as_matrix(R), dt=T, yaw_rate=yaw_rate)
    x0 = np.asarray(x0, float)
    Lq = np.linalg.cholesky(model.Q)
    Lr = np.linalg.cholesky(model.R)
    w = rng.standard_normal((steps, 6)) @ Lq.T
    v = rng.standard_normal((steps, 3)) @ Lr.T
    if not truth_noise:
        w[:] = 0.0
    if mixture_eps > 0:
        outlier = rng.random(steps) < mixture_eps
        v[outlier] *= np.sqrt(mixture_scale)
    x = np.empty((steps, 6))
    prev = x0
    for k in range(steps):
        prev = model.f(prev, k) + w[k]
        prev[4:] = wrap(prev[4:])
        x[k] = prev
    z = model.h(x, 0) + v
    z[:, 1:] = wrap(z[:, 1:])
    t = T * np.arange(1, steps + 1)
    ref = {
        "position": Channel(x[:, :3], "m", "ENU local (sonar at origin)", components=("x", "y", "z")),
        "speed": Channel(x[:, 3], "m/s", "body"),
        "attitude": Channel(
            x[:, 4:],
            "rad",
            "ENU local",
            components=("pitch", "yaw"),
            angles=(0, 1),
            convention="pitch positive nose down; yaw 0 = east, counter-clockwise",
        ),
    }
    sonar = Channel(
        z,
        "m, rad, rad",
        "sonar at origin",
        components=("range", "elevation", "azimuth"),
        angles=(1, 2),
        description="single active sonar (002 §1.2)",
    )
    meta = {"source": "synthetic: replay.sim.auv_sonar", "synthetic": True, "crs": None}
    sim = Simulation(dt=T, initial_state=x0, state=STATE)  # the sonar at the model's origin (0, 0, 0)
    return Frame(t, {"sonar": sonar}, ref, None, meta, simulation=sim)
