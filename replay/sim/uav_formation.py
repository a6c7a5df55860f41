"""``sim/uav-formation``: leader and follower UAVs under glint noise (paper 003, §4).

The paper's figures: leader starts at (520 m, 560 m) with velocity (50, 50)
m/s; follower x₀ = [400 m, 400 m, 50 m/s, 50 m/s]; range σ = 5 m; bearing σ₁ =
0.4π/180 (thermal) and σ₂ = 0.8π/180 (glint); glint strength ε = 0.75.
Glint noise (:class:`replay.noise.Glint`): (1 − ε) N(0, diag(5², σ₁²)) +
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
from replay.frame import Channel, Frame
from replay.models.formation import Formation
from replay.noise import Glint

DEG = np.pi / 180
X0_FOLLOWER = (400.0, 400.0, 50.0, 50.0)
X0_LEADER = (520.0, 560.0, 50.0, 50.0)


def glint_003(eps: float = 0.75, range_sigma: float = 5.0, sigma1: float = 0.4 * DEG,
              sigma2: float = 0.8 * DEG) -> Glint:
    return Glint(np.diag([range_sigma**2, sigma1**2]), np.diag([range_sigma**2, sigma2**2]), eps)


def turn_schedule(steps: int, leg: int, rate: float) -> np.ndarray:
    pattern = np.array([0.0, rate, 0.0, -rate])
    return pattern[(np.arange(steps) // leg) % 4]


def make_frame(rng: np.random.Generator, *, steps: int = 100, T: float = 1.0, leg: int = 20,
               turn_rate: float = 0.05, accel_sigma: float = 1.0, eps: float = 0.75,
               range_sigma: float = 5.0, sigma1: float = 0.4 * DEG, sigma2: float = 0.8 * DEG,
               x0=X0_FOLLOWER, leader0=X0_LEADER) -> Frame:
    noise = glint_003(eps, range_sigma, sigma1, sigma2)
    w = turn_schedule(steps, leg, turn_rate)
    lead = np.empty((steps, 4))
    fol = np.empty((steps, 4))
    xl, xf = np.asarray(leader0, float), np.asarray(x0, float)
    dummy = Formation(np.zeros((steps, 2)), w, T, accel_sigma**2 * np.eye(2), noise)
    for k in range(steps):  # first sample one step after x0
        xl = dummy.f(xl, k)
        xf = dummy.sample_f(xf, k, rng)
        lead[k], fol[k] = xl, xf
    d = lead[:, :2] - fol[:, :2]  # eq. 6 for every step at once
    z = np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])])
    z = z + noise.sample(rng, steps)
    z[:, 1] = wrap(z[:, 1])
    t = T * np.arange(1, steps + 1)
    channels = {
        "radar": Channel(z, "m, rad", "follower", components=("range", "bearing"), angles=(1,),
                         convention="bearing: 0 = east (x), counter-clockwise positive",
                         description="ranging radar on the follower, glint noise (003 eq. 7-10)"),
        "leader_position": Channel(lead[:, :2], "m", "local x east, y north", components=("x", "y")),
        "turn_rate": Channel(w, "rad/s", "", description="commanded turn rate (eq. 3), > 0 left"),
    }
    reference = {
        "position": Channel(fol[:, :2], "m", "local x east, y north", components=("x", "y")),
        "velocity": Channel(fol[:, 2:], "m/s", "local x east, y north", components=("vx", "vy")),
    }
    meta = {"source": "synthetic: replay.sim.uav_formation", "synthetic": True, "crs": None, "dt": T,
            "initial_state": list(map(float, x0)), "accel_sigma": accel_sigma, "eps": eps,
            "range_sigma": range_sigma, "sigma1": sigma1, "sigma2": sigma2}
    return Frame(t, channels, reference, None, meta)
