"""``sim/sauv-current``: paper 001's small AUV in a meandering-jet current (§5).

The truth: the A→G mission of 001 Fig. 2 flown through the water, plus the
ocean current of eq. 111–115; the sensors: depth gauge, DVL and AHRS with the
error budget of 001 §5 and Table 1. Seeded: every random number comes from
the ``rng`` passed in.

**Current field** (eq. 111–115), uniform over depth, no vertical component:

    Psi(x, y, t) = 1 − tanh[(y − B(t) cos(λ(x − ct))) / (1 + λ² B(t)² sin²(λ(x − ct)))^½]
    B(t) = 1.2 + 0.3 cos(0.4 t + π/2),  c = 0.12,  λ = 0.84
    U_N = ∂Psi/∂x,  U_E = −∂Psi/∂y,  A_N = ∂U_N/∂t,  A_E = ∂U_E/∂t

Choices: (1) *axes*: x is **east** and y **north**; with eq. 112–113 this is
the only assignment under which Psi is a stream function (∇·U = 0; tested).
(2) *units*: the jet is non-dimensional; coordinates are scaled by
``length_scale`` metres (x = east/L) and velocities by ``strength`` m/s (the
paper's "scale the field up for complex sea states" knob); t is in seconds as
printed. (3) the paper samples the field on an 8 m grid (``grid`` = 8, the
value of the cell centre; ``grid=0`` for the continuous field).
(4) body acceleration: the paper adds the current's local acceleration
(eq. 114–115) to the vehicle's through-water acceleration; we do the same,
rotated into the body frame (rotation-rate terms neglected, as in the paper).

**Mission A→G** (001 §4): AB accelerate at 0.2 m/s² to 4 kn at the surface; BC
dive at 4 kn to 30 m; CD decelerate at −0.2 m/s² to 2 kn; DE cruise; EF climb
at 2 kn to the surface; FG decelerate at −0.1 m/s² to rest. Roll is zero.
Not printed, ours: dive/climb pitch ±``dive_pitch_deg`` (20°), cruise of
``cruise_s`` s with a 90° turn to starboard and one back at 3°/s, initial
heading ``heading0_deg`` (45°), steps of T = 0.5 s.

**Sensors** (001 §5): depth gauge 3 % of a ``depth_full_scale`` (50 m, ours)
full scale, white; DVL 1 % of speed per axis, in the body frame, with
``dvl_track`` (the paper does not say which; ours):

- ``"bottom"`` (default): bottom lock, velocity over ground. The current is
  then *in* the measurement: a filter that integrates the DVL velocity sees
  the current's effect on position, which is no model error at all.
- ``"water"``: water track, velocity relative to the water (the through-water
  velocity of the mission), 1 % of that speed. The current is then a true
  unmodelled drift: the model of :mod:`replay.models.sauv` integrates the
  body velocity it is given into position, no sensor measures position or the
  current, so north/east carry the integral of the current as an error that
  no filter with this sensor suite can observe (the accelerometers still
  measure the over-ground acceleration, current's local acceleration included).

Accelerometers: bias 0.02 m/s² (1σ, constant over a
run) plus white 0.02 m/(s² √Hz); AHRS roll, pitch, heading: 2° (1σ) dynamic
accuracy, a first-order Gauss–Markov error with correlation time ``ahrs_tau``
(ours, 30 s; 0 = white). The gyro and magnetometer figures of Table 1 are
internal to the AHRS, whose output accuracy (2°) is what the filters see.

**Channels** (frame conventions of replay/frame.py, as a real log maps):
``depth`` (m, positive down), ``dvl_velocity`` [vx, vy, vz] (m/s, body
forward-starboard-down), ``accel`` [ax, ay, az] (m/s², body FSD),
``attitude`` [roll, pitch, yaw] in the Bohai adapter's convention (roll
positive left side up, pitch positive front down, yaw 0 = east,
counter-clockwise). **Reference**: ``position`` [east, north, up] (ENU, m),
``velocity_body`` and ``accel_body`` (body FSD), ``attitude`` (same convention
as the channel), ``current`` [east, north] (m/s). The filter model runs in NED
(:mod:`replay.models.sauv`); the task converts.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from replay.util.angles import wrap
from replay.frame import Channel, Frame, Simulation
from replay.models.sauv import COMPONENTS, DEG, KNOT, body_to_level
from replay.util.params import Param

from . import Numbers, generator

LAMBDA, C_PHASE = 0.84, 0.12
ATT_CONVENTION = (
    "roll: positive = left side up; pitch: positive = front down; "
    "yaw: heading, 0 = east, counter-clockwise positive (ENU)"
)


def meander_B(t):
    return 1.2 + 0.3 * np.cos(0.4 * t + np.pi / 2)


def stream_function(x, y, t):
    """Psi of eq. 111 (non-dimensional x = east, y = north)."""
    s = LAMBDA * (x - C_PHASE * t)
    B = meander_B(t)
    return 1.0 - np.tanh((y - B * np.cos(s)) / np.sqrt(1 + (LAMBDA * B * np.sin(s)) ** 2))


def current_velocity(x, y, t):
    """(U_E, U_N) of eq. 112–113, non-dimensional, analytic derivatives of Psi."""
    s = LAMBDA * (x - C_PHASE * t)
    B = meander_B(t)
    den = np.sqrt(1 + (LAMBDA * B * np.sin(s)) ** 2)
    num = y - B * np.cos(s)
    eta = num / den
    sech2 = 1.0 / np.cosh(eta) ** 2
    deta_dy = 1.0 / den
    dden_dx = LAMBDA**3 * B**2 * np.sin(s) * np.cos(s) / den
    deta_dx = (LAMBDA * B * np.sin(s) * den - num * dden_dx) / den**2
    u_n = -sech2 * deta_dx  # dPsi/dx
    u_e = sech2 * deta_dy  # -dPsi/dy
    return u_e, u_n


def current_acceleration(x, y, t, h: float = 1e-4):
    """(A_E, A_N) of eq. 114–115: local time derivatives (central difference)."""
    e1, n1 = current_velocity(x, y, t + h)
    e0, n0 = current_velocity(x, y, t - h)
    return (e1 - e0) / (2 * h), (n1 - n0) / (2 * h)


def mission(T=0.5, dive_pitch_deg=20.0, cruise_s=300.0, depth=30.0, heading0_deg=45.0, turn_rate_deg=3.0):
    """Through-water surge speed u(t), pitch (NED, nose up +), heading (NED) at steps of T."""
    fast, slow = 4 * KNOT, 2 * KNOT
    th = dive_pitch_deg * DEG
    legs = [
        ("AB", fast / 0.2, 0.2, 0.0),
        ("BC", depth / (fast * np.sin(th)), 0.0, -th),
        ("CD", (fast - slow) / 0.2, -0.2, 0.0),
        ("DE", cruise_s, 0.0, 0.0),
        ("EF", depth / (slow * np.sin(th)), 0.0, th),
        ("FG", slow / 0.1, -0.1, 0.0),
    ]
    t_end = sum(leg[1] for leg in legs)
    t = np.arange(0.0, t_end + 1e-9, T)
    u, pitch = np.zeros_like(t), np.zeros_like(t)
    start, speed = 0.0, 0.0
    for _, dur, acc, p in legs:
        inside = (t >= start) & (t < start + dur)
        u[inside] = speed + acc * (t[inside] - start)
        pitch[inside] = p
        start, speed = start + dur, speed + acc * dur
    u[t >= start] = 0.0
    # heading: two 90 deg turns during the cruise (starboard, then back to port)
    t_de = sum(leg[1] for leg in legs[:3])
    turn = 90.0 / turn_rate_deg
    rate = np.zeros_like(t)
    a, b = t_de + 0.25 * cruise_s, t_de + 0.65 * cruise_s
    rate[(t >= a) & (t < a + turn)] = turn_rate_deg * DEG
    rate[(t >= b) & (t < b + turn)] = -turn_rate_deg * DEG
    heading = heading0_deg * DEG + np.concatenate([[0.0], np.cumsum(rate[:-1]) * T])
    return t, u, pitch, wrap(heading)


def gauss_markov(rng, n, sigma, tau, T):
    """Stationary first-order Gauss-Markov sequences (n, k) of std ``sigma``."""
    sigma = np.atleast_1d(np.asarray(sigma, float))
    e = rng.standard_normal((n, len(sigma))) * sigma
    if tau <= 0:
        return e
    phi = np.exp(-T / tau)
    out = np.empty_like(e)
    out[0] = e[0]
    c = np.sqrt(1 - phi**2)
    for k in range(1, n):
        out[k] = phi * out[k - 1] + c * e[k]
    return out


PARAMS = (
    Param("T", float, 0.5, "time step (ours)", unit="s", low=0, low_open=True),
    Param("strength", float, 0.5, "current velocity scale (the jet is non-dimensional)", unit="m/s", low=0),
    Param("length_scale", float, 100.0, "metres per non-dimensional unit of the jet", unit="m", low=0, low_open=True),
    Param("grid", float, 8.0, "cell of the sampled current field (001: 8 m); 0 = continuous", unit="m", low=0),
    Numbers("origin_en", list, (0.0, 0.0), "start point [east, north]", unit="m", length=2),
    Param(
        "dive_pitch_deg",
        float,
        20.0,
        "pitch of the dive and the climb (ours)",
        unit="deg",
        low=0,
        high=90,
        low_open=True,
        high_open=True,
    ),
    Param("cruise_s", float, 300.0, "duration of the cruise leg DE (ours)", unit="s", low=0),
    Param("heading0_deg", float, 45.0, "initial heading, NED (ours)", unit="deg"),
    Param(
        "depth_full_scale",
        float,
        50.0,
        "depth gauge full scale; its noise is 3 % of it (ours)",
        unit="m",
        low=0,
        low_open=True,
    ),
    Param(
        "dvl_track",
        str,
        "bottom",
        "DVL reference: bottom lock (velocity over ground) or water track "
        "(velocity through the water: the current becomes an unmodelled drift) (ours; 001 is silent)",
        choices=("bottom", "water"),
    ),
    Param(
        "dvl_percent", float, 1.0, "DVL noise standard deviation, percent of speed per axis (001 §5)", unit="%", low=0
    ),
    Param(
        "acc_bias",
        float,
        0.02,
        "accelerometer bias standard deviation, constant over a run (001 §5)",
        unit="m/s^2",
        low=0,
    ),
    Param(
        "acc_noise_density", float, 0.02, "accelerometer white noise density (001 §5)", unit="m/(s^2 sqrt(Hz))", low=0
    ),
    Param(
        "ahrs_sigma_deg",
        float,
        2.0,
        "AHRS roll, pitch and heading error standard deviation (001 §5)",
        unit="deg",
        low=0,
    ),
    Param("ahrs_tau", float, 30.0, "correlation time of the AHRS error (ours); 0 = white", unit="s", low=0),
)


def _truth(t, u, pitch, heading, T, origin_en, grid, length_scale, strength):
    """The vehicle flown through the current: NED position, current, body velocity and acceleration."""
    n = len(t)
    roll = np.zeros(n)
    C = body_to_level(pitch, roll)  # (n, 3, 3)
    ch, sh = np.cos(heading), np.sin(heading)
    Rz = np.zeros((n, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = ch, -sh, sh, ch, 1.0
    Cnb = Rz @ C  # body -> NED
    v_water = Cnb[:, :, 0] * u[:, None]  # through-water velocity, NED
    a_water = np.gradient(v_water, T, axis=0)
    pos = np.zeros((n, 3))  # NED
    pos[0, :2] = origin_en[1], origin_en[0]
    cur = np.zeros((n, 3))
    cur_acc = np.zeros((n, 3))

    def field(p, tk):
        e, nn = p[1], p[0]
        if grid > 0:
            e, nn = (np.floor(e / grid) + 0.5) * grid, (np.floor(nn / grid) + 0.5) * grid
        ue, un = current_velocity(e / length_scale, nn / length_scale, tk)
        ae, an = current_acceleration(e / length_scale, nn / length_scale, tk)
        return np.array([un, ue, 0.0]) * strength, np.array([an, ae, 0.0]) * strength

    for k in range(n):
        cur[k], cur_acc[k] = field(pos[k], t[k])
        if k + 1 < n:
            pos[k + 1] = pos[k] + T * (0.5 * (v_water[k] + v_water[k + 1]) + cur[k])
    pos[:, 2] = np.maximum(pos[:, 2], 0.0)
    v_ned = v_water + cur
    v_b = np.einsum("nji,nj->ni", Cnb, v_ned)  # Cnb^T v
    a_b = np.einsum("nji,nj->ni", Cnb, a_water + cur_acc)
    return SimpleNamespace(n=n, roll=roll, Cnb=Cnb, v_water=v_water, pos=pos, cur=cur, v_b=v_b, a_b=a_b)


def _sensors(rng, tr, pitch, heading, T, p):
    """Depth, DVL, accelerometers and AHRS attitude of the truth ``tr``, drawn from ``rng`` in a fixed order."""
    n = tr.n
    depth = tr.pos[:, 2] + rng.standard_normal(n) * 0.03 * p.depth_full_scale
    # water track: Cnb^T v_water
    v_dvl = tr.v_b if p.dvl_track == "bottom" else np.einsum("nji,nj->ni", tr.Cnb, tr.v_water)
    speed = np.linalg.norm(v_dvl, axis=1, keepdims=True)
    dvl = v_dvl + rng.standard_normal((n, 3)) * (p.dvl_percent / 100.0) * np.maximum(speed, 0.05)
    acc = tr.a_b + p.acc_bias * rng.standard_normal(3) + rng.standard_normal((n, 3)) * p.acc_noise_density / np.sqrt(T)
    att_err = gauss_markov(rng, n, [p.ahrs_sigma_deg * DEG] * 3, p.ahrs_tau, T)
    # Bohai-style attitude: roll same sign as NED, pitch front-down positive, yaw ENU
    att_true = np.column_stack([tr.roll, -pitch, wrap(np.pi / 2 - heading)])
    att_meas = att_true + att_err
    att_meas[:, 2] = wrap(att_meas[:, 2])
    return SimpleNamespace(depth=depth, dvl=dvl, acc=acc, att_true=att_true, att_meas=att_meas)


BODY = "body forward-starboard-down"


def _channels(sn, dvl_track):
    """The frame's sensor channels."""
    return {
        "depth": Channel(sn.depth, "m", "positive down", description="depth gauge, 3 % of full scale"),
        "dvl_velocity": Channel(
            sn.dvl,
            "m/s",
            BODY,
            components=("vx", "vy", "vz"),
            description="DVL bottom-lock velocity over ground, 1 %"
            if dvl_track == "bottom"
            else "DVL water-track velocity through the water, 1 %",
        ),
        "accel": Channel(
            sn.acc,
            "m/s^2",
            BODY,
            components=("ax", "ay", "az"),
            description="AHRS accelerometers (kinematic acceleration, no gravity)",
        ),
        "attitude": Channel(
            sn.att_meas,
            "rad",
            "body",
            components=("roll", "pitch", "yaw"),
            angles=(0, 1, 2),
            convention=ATT_CONVENTION,
            description="AHRS, 2 deg",
        ),
    }


def _reference(tr, att_true):
    """The frame's reference: the truth, in the channels' conventions."""
    pos = tr.pos
    return {
        "position": Channel(
            np.column_stack([pos[:, 1], pos[:, 0], -pos[:, 2]]), "m", "ENU local", components=("east", "north", "up")
        ),
        "velocity_body": Channel(tr.v_b, "m/s", BODY, components=("vx", "vy", "vz")),
        "accel_body": Channel(tr.a_b, "m/s^2", BODY, components=("ax", "ay", "az")),
        "attitude": Channel(
            att_true, "rad", "body", components=("roll", "pitch", "yaw"), angles=(0, 1, 2), convention=ATT_CONVENTION
        ),
        "current": Channel(tr.cur[:, [1, 0]], "m/s", "ENU local", components=("east", "north")),
    }


@generator(PARAMS, record=True)
def make_frame(rng: np.random.Generator, p) -> Frame:
    """Simulate the A→G mission in the current field; sensors from ``rng``."""
    t, u, pitch, heading = mission(p.T, p.dive_pitch_deg, p.cruise_s, 30.0, p.heading0_deg)
    tr = _truth(t, u, pitch, heading, p.T, p.origin_en, p.grid, p.length_scale, p.strength)
    noise = SimpleNamespace(
        depth_full_scale=p.depth_full_scale,
        dvl_track=p.dvl_track,
        dvl_percent=p.dvl_percent,
        acc_bias=p.acc_bias,
        acc_noise_density=p.acc_noise_density,
        ahrs_sigma_deg=p.ahrs_sigma_deg,
        ahrs_tau=p.ahrs_tau,
    )
    sn = _sensors(rng, tr, pitch, heading, p.T, noise)
    meta = {
        "source": "synthetic: replay.sim.sauv_current",
        "synthetic": True,
        "crs": None,
    }
    x0 = np.concatenate([tr.pos[0], tr.v_b[0], tr.a_b[0], [heading[0]]])  # the NED state at the first sample
    sim = Simulation(dt=p.T, initial_state=x0, state=COMPONENTS)
    return Frame(t, _channels(sn, p.dvl_track), _reference(tr, sn.att_true), None, meta, simulation=sim)
