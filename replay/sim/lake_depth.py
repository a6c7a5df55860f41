"""``sim/lake-depth``: synthetic lake-trial depth logs for paper 000 (GPF). SYNTHETIC DATA.

The paper's lake-trial data are not published. This generator makes logs of
the same kind: an AUV's own depth gauge, speed sensor and pitch sensor at
T = 0.05 s, and the true trajectory as the "external reference".

Trajectory (deterministic, so that RMSE over time lines up across Monte Carlo
runs): the vehicle follows a schedule of commanded pitch and speed
(:data:`PROFILE`) — level runs, dives, climbs and a train of pitch steps. Pitch
follows its command through a first-order lag (``tau_pitch`` = 0.5 s) with a
rate limit (``max_pitch_rate`` = 15 deg/s), speed through a first-order lag
(``tau_speed`` = 2 s), and depth integrates eq. 4 without noise,
z_k = z_{k-1} + v_{k-1} sin(phi_{k-1}) T (pitch positive nose down).
``meta["maneuvers"]`` lists the segments with a non-zero pitch command (plus
``settle`` = 1.5 s after each), labelled.

Sensor noise (white, Gaussian) with a standard deviation that changes over time:

    sigma_c(t) = base_c * regime(t) * (1 + drift * t / duration)

``regime`` is piecewise constant over equal parts of the run
(``regimes`` = (1, 3, 0.5, 2)); ``drift`` = 0.5 is the slow rise;
``base`` = (0.05 m, 0.05 m/s, 0.5 deg). ``meta["noise"]`` records them.

The reference is the truth at every sensor sample, unless ``ref_every`` > 1
(reference at a lower rate) or ``ref_gaps`` (list of [t0, t1) seconds without
reference) say otherwise: then those reference samples are marked invalid (not
interpolated: aligning is the adapter's job when a file is read back).
"""
from __future__ import annotations

import numpy as np

from replay.frame import Channel, Frame
from replay.util.params import Param

from . import Intervals, Numbers, generator

T = 0.05
REGIMES = (1.0, 3.0, 0.5, 2.0)
DRIFT = 0.5
# (start s, end s, commanded pitch deg, commanded speed m/s, label); level runs in between
PROFILE = (
    (0.0, 10.0, 0.0, 1.5, "level"),
    (10.0, 22.0, 20.0, 1.5, "dive"),
    (22.0, 32.0, 0.0, 1.5, "level"),
    (32.0, 35.0, 10.0, 1.5, "pitch steps"),
    (35.0, 38.0, -10.0, 1.5, "pitch steps"),
    (38.0, 41.0, 10.0, 1.5, "pitch steps"),
    (41.0, 44.0, -10.0, 1.5, "pitch steps"),
    (44.0, 54.0, -25.0, 2.0, "climb"),
    (54.0, 66.0, 0.0, 1.2, "level"),
    (66.0, 76.0, 15.0, 1.2, "dive"),
    (76.0, 90.0, 0.0, 1.2, "level"),
)
PITCH_CONVENTION = "pitch positive nose down (depth grows with positive pitch)"
EXAMPLE = {"ref_every": 2, "ref_gaps": [[30.0, 30.3], [60.0, 62.0]]}


def commands(t: np.ndarray):
    """Commanded pitch (rad) and speed (m/s) at times ``t`` (level after the profile)."""
    pitch = np.zeros_like(t)
    speed = np.full_like(t, PROFILE[-1][3])
    for t0, t1, p, v, _ in PROFILE:
        sel = (t >= t0) & (t < t1)
        pitch[sel] = np.deg2rad(p)
        speed[sel] = v
    return pitch, speed


def maneuvers(duration: float, settle: float = 1.5) -> list[list]:
    """[[t0, t1, label], ...]: segments with a non-zero pitch command, merged, plus settling."""
    out: list[list] = []
    for t0, t1, p, _, label in PROFILE:
        if p == 0.0 or t0 >= duration:
            continue
        end = min(t1 + settle, duration)
        if out and t0 <= out[-1][1]:  # overlapping (settling): one segment
            out[-1][1] = max(out[-1][1], end)
            if label not in out[-1][2]:
                out[-1][2] += f", {label}"
        else:
            out.append([t0, end, label])
    return out


def trajectory(n: int, dt: float = T, depth0: float = 3.0, tau_pitch: float = 0.5,
               max_pitch_rate: float = 15.0, tau_speed: float = 2.0) -> np.ndarray:
    """True states [depth, speed, pitch] (n, 3) at t = 0, dt, ..., following the profile."""
    t = dt * np.arange(n)
    pc, vc = commands(t)
    x = np.empty((n, 3))
    z, v, phi = depth0, vc[0], pc[0]
    rate = np.deg2rad(max_pitch_rate) * dt
    for k in range(n):
        x[k] = z, v, phi
        z = z + v * np.sin(phi) * dt
        phi = phi + np.clip((pc[k] - phi) * dt / tau_pitch, -rate, rate)
        v = v + (vc[k] - v) * dt / tau_speed
    return x


def noise_sigma(t: np.ndarray, duration: float, base, regimes, drift: float) -> np.ndarray:
    """sigma (n, 3) of each sensor at times ``t`` (module docstring)."""
    part = np.minimum((t / duration * len(regimes)).astype(int), len(regimes) - 1)
    factor = np.asarray(regimes, float)[part] * (1.0 + drift * t / duration)
    return factor[:, None] * np.asarray(base, float)


def base_for_rms(target, duration: float = 90.0, dt: float = T, regimes=REGIMES,
                 drift: float = DRIFT) -> tuple:
    """``base_sigma`` whose sigma_c(t) has root-mean-square ``target[c]`` over the run.

    Used to put the sensors at the level of a filter's fixed R (R's std = the
    sensor's RMS noise, the regimes and drift varying around it).
    """
    t = dt * np.arange(int(round(duration / dt)))
    f = noise_sigma(t, duration, (1.0,), regimes, drift)[:, 0]
    return tuple(float(v) for v in np.asarray(target, float) / np.sqrt(np.mean(f * f)))


PARAMS = (
    Param("duration", float, 90.0, "length of the log", unit="s", low=0, low_open=True),
    Param("dt", float, T, "sample period", unit="s", low=0, low_open=True),
    Param("depth0", float, 3.0, "initial depth", unit="m"),
    Numbers("base_sigma", list, (0.05, 0.05, float(np.deg2rad(0.5))),
            "base noise standard deviations of the depth, speed and pitch sensors", unit="m, m/s, rad",
            length=3, low=0),
    Numbers("regimes", list, REGIMES, "noise factor of each equal part of the run", low=0),
    Param("drift", float, DRIFT, "slow rise of the noise: factor 1 + drift t / duration", low=0),
    Param("ref_every", int, 1, "reference at every ref_every-th sample", low=1),
    Intervals("ref_gaps", list, (), "[t0, t1) spans without reference", unit="s"),
)


@generator(PARAMS)
def make_frame(rng: np.random.Generator, *, duration, dt, depth0, base_sigma, regimes, drift, ref_every,
               ref_gaps) -> Frame:
    """A synthetic lake-trial frame: sensors in ``channels``, truth in ``reference``."""
    n = int(round(duration / dt))
    t = dt * np.arange(n)
    x = trajectory(n, dt, depth0)
    sigma = noise_sigma(t, duration, base_sigma, regimes, drift)
    z = x + sigma * rng.standard_normal((n, 3))
    ref_ok = np.zeros(n, bool)
    ref_ok[::ref_every] = True
    for t0, t1 in ref_gaps:
        ref_ok &= ~((t >= t0) & (t < t1))
    desc = {"depth": "depth gauge, positive down", "speed": "speed sensor, forward",
            "pitch": f"pitch sensor, {PITCH_CONVENTION}"}
    units = {"depth": ("m", "down"), "speed": ("m/s", "body forward"), "pitch": ("rad", "body")}
    channels, reference = {}, {}
    for i, name in enumerate(("depth", "speed", "pitch")):
        unit, frame = units[name]
        angles = (0,) if name == "pitch" else ()
        conv = PITCH_CONVENTION if name == "pitch" else ""
        channels[name] = Channel(z[:, i], unit, frame, None, (name,), angles, conv, desc[name])
        reference[name] = Channel(np.where(ref_ok, x[:, i], np.nan), unit, frame, ref_ok, (name,),
                                  angles, conv, f"true {name} (synthetic external reference)")
    meta = {"source": "synthetic: replay.sim.lake_depth", "synthetic": True, "dt": dt,
            "maneuvers": maneuvers(duration), "pitch_convention": PITCH_CONVENTION,
            "noise": {"base_sigma": list(base_sigma), "regimes": list(regimes), "drift": drift},
            "columns": {"depth": "depth", "speed": "speed", "pitch": "pitch"},
            "ref_every": int(ref_every), "ref_gaps": [list(g) for g in ref_gaps]}
    return Frame(t, channels, reference, None, meta)


def write_example(path, rng: np.random.Generator, **params) -> Frame:
    """Write one synthetic lake-trial log (reference at half rate, one short and one long gap)."""
    from replay.adapters.lake import write

    frame = make_frame(rng, **{**EXAMPLE, **params})
    write(frame, path, comments=[
        "SYNTHETIC: generated by replay.sim.lake_depth (`replay datasets make sim/lake-depth`), "
        "not a lake trial",
        "synthetic: true",
        f"convention: depth positive down; {PITCH_CONVENTION}",
        "maneuvers: " + "; ".join(f"{a:g}-{b:g} {lab}" for a, b, lab in frame.meta["maneuvers"]),
    ])
    return frame
