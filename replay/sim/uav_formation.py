"""``sim/uav-formation``: leader and follower UAVs under glint noise (paper 003, §4).

The paper's figures: leader starts at (520 m, 560 m) with velocity (50, 50)
m/s; follower x₀ = [400 m, 400 m, 50 m/s, 50 m/s]; range σ = 5 m; bearing σ₁ =
0.4π/180 (thermal) and σ₂ = 0.8π/180 (glint); glint strength ε = 0.75.
Glint noise (:class:`replay.models.noise.Glint`): (1 − ε) N(0, diag(5², σ₁²)) +
ε N(0, diag(5², σ₂²)) on [range, bearing] (our reading: the 5 m range σ holds
in both components, the glint widens the bearing).

Not printed, ours: T = 1 s; 100 steps in five legs of 20 — straight, left
turn, straight, right turn, straight — with |w| = ``turn_rate`` = 0.05 rad/s
(eq. 3; both aircraft fly the same commanded turns); leader noise-free (it
navigates with GPS/INS); follower acceleration noise Q_a = ``accel_sigma``² I
(1 m/s²).

Channels: ``radar`` [range, bearing] (bearing 0 = east, counter-clockwise),
``leader_position`` [x, y] (what the leader transmits), ``turn_rate`` (rad/s,
the follower's own commanded turns). Reference: the follower's
``position`` [x, y] and ``velocity`` [vx, vy] (x east, y north, metres).
"""

from __future__ import annotations

import numpy as np

from replay.util.angles import wrap
from replay.frame import Channel, Frame, Simulation
from replay.models.formation import Formation
from replay.models.noise import Glint
from replay.util.params import Param

from . import Numbers, generator

DEG = np.pi / 180
X0_FOLLOWER = (400.0, 400.0, 50.0, 50.0)
X0_LEADER = (520.0, 560.0, 50.0, 50.0)


def glint_003(eps: float, range_sigma: float, sigma1: float, sigma2: float) -> Glint:
    """(1 - eps) N(0, diag(range_sigma^2, sigma1^2)) + eps N(0, diag(range_sigma^2, sigma2^2)) (003 eq. 8)."""
    return Glint(np.diag([range_sigma**2, sigma1**2]), np.diag([range_sigma**2, sigma2**2]), eps)


def turn_schedule(steps: int, leg: int, rate: float) -> np.ndarray:
    pattern = np.array([0.0, rate, 0.0, -rate])
    return pattern[(np.arange(steps) // leg) % 4]


PARAMS = (
    Param("steps", int, 100, "number of samples (t = T, ..., steps T)", low=1),
    Param("T", float, 1.0, "time step (ours)", unit="s", low=0, low_open=True),
    Param("leg", int, 20, "steps per leg of the straight / left / straight / right pattern (ours)", low=1),
    Param("turn_rate", float, 0.05, "|w| of the commanded turns, eq. 3 (ours)", unit="rad/s"),
    Param(
        "accel_sigma",
        float,
        1.0,
        "follower acceleration noise standard deviation (ours)",
        unit="m/s^2",
        low=0,
        low_open=True,
    ),
    Param("eps", float, 0.75, "glint probability epsilon (003 §4.1)", low=0, high=1),
    Param("range_sigma", float, 5.0, "range noise standard deviation (003 §4.1)", unit="m", low=0, low_open=True),
    Param(
        "sigma1",
        float,
        0.4 * DEG,
        "thermal bearing noise standard deviation (003 §4.1)",
        unit="rad",
        low=0,
        low_open=True,
    ),
    Param(
        "sigma2",
        float,
        0.8 * DEG,
        "glint bearing noise standard deviation (003 §4.1)",
        unit="rad",
        low=0,
        low_open=True,
    ),
    Numbers("x0", list, X0_FOLLOWER, "follower initial state [x, y, vx, vy] (003 §4.1)", unit="m, m/s", length=4),
    Numbers("leader0", list, X0_LEADER, "leader initial state [x, y, vx, vy] (003 §4.1)", unit="m, m/s", length=4),
)


@generator(PARAMS, record=True)
def make_frame(rng: np.random.Generator, p) -> Frame:
    """Simulate ``p.steps`` samples of both aircraft and the follower's radar from ``rng``."""
    noise = glint_003(p.eps, p.range_sigma, p.sigma1, p.sigma2)
    w = turn_schedule(p.steps, p.leg, p.turn_rate)
    lead = np.empty((p.steps, 4))
    fol = np.empty((p.steps, 4))
    xl, xf = np.asarray(p.leader0, float), np.asarray(p.x0, float)
    dummy = Formation(np.zeros((p.steps, 2)), w, p.T, p.accel_sigma**2 * np.eye(2), noise)
    for k in range(p.steps):  # first sample one step after x0
        xl = dummy.f(xl, k)
        xf = dummy.sample_f(xf, k, rng)
        lead[k], fol[k] = xl, xf
    d = lead[:, :2] - fol[:, :2]  # eq. 6 for every step at once
    z = np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])])
    z = z + noise.sample(rng, p.steps)
    z[:, 1] = wrap(z[:, 1])
    t = p.T * np.arange(1, p.steps + 1)
    channels = {
        "radar": Channel(
            z,
            "m, rad",
            "follower",
            components=("range", "bearing"),
            angles=(1,),
            convention="bearing: 0 = east (x), counter-clockwise positive",
            description="ranging radar on the follower, glint noise (003 eq. 7-10)",
        ),
        "leader_position": Channel(lead[:, :2], "m", "local x east, y north", components=("x", "y")),
        "turn_rate": Channel(w, "rad/s", "", description="commanded turn rate (eq. 3), > 0 left"),
    }
    reference = {
        "position": Channel(fol[:, :2], "m", "local x east, y north", components=("x", "y")),
        "velocity": Channel(fol[:, 2:], "m/s", "local x east, y north", components=("vx", "vy")),
    }
    meta = {
        "source": "synthetic: replay.sim.uav_formation",
        "synthetic": True,
        "crs": None,
    }
    sim = Simulation(dt=p.T, initial_state=p.x0, state=("x", "y", "vx", "vy"))  # the follower's x0
    return Frame(t, channels, reference, None, meta, simulation=sim)
