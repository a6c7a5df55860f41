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
``Frame.maneuvers`` lists the segments with a non-zero pitch command (plus
``settle`` = 1.5 s after each), labelled.

``profile_seed`` (default null: the fixed :data:`PROFILE`) replaces the schedule by
a random one, :func:`random_profile`, drawn from its own generator seeded by
``profile_seed`` alone: every Monte Carlo run of a configuration follows the same
trajectory (only the sensor noise changes with the run), and two configurations
with the same ``profile_seed`` share it.

Sensor noise (white, Gaussian) with a standard deviation that changes over time:

    sigma_c(t) = base_c * regime(t) * (1 + drift * t / duration)

``regime`` is piecewise constant over equal parts of the run
(``regimes`` = (1, 3, 0.5, 2)); ``drift`` = 0.5 is the slow rise;
``base`` = (0.05 m, 0.05 m/s, 0.5 deg). ``meta["noise"]`` records them.
``noise_rms`` (default null) sets the level instead of ``base_sigma``: the
root-mean-square over the run of each sensor's sigma_c(t) (:func:`base_for_rms`),
the regimes and drift varying around it. Paper 000's reproduction uses it to put
the sensors at a multiple of the baselines' fixed R (``noise_rms`` = rho * sqrt(diag R)).

The reference is the truth at every sensor sample, unless ``ref_every`` > 1
(reference at a lower rate) or ``ref_gaps`` (list of [t0, t1) seconds without
reference) say otherwise: then those reference samples are marked invalid (not
interpolated: aligning is the adapter's job when a file is read back).
"""

from __future__ import annotations

import numpy as np

from replay.frame import Channel, Frame, Simulation
from replay.util.params import Param

from . import Intervals, Numbers, generator

T = 0.05
REGIMES = (1.0, 3.0, 0.5, 2.0)
DRIFT = 0.5
BASE_SIGMA = (0.05, 0.05, float(np.deg2rad(0.5)))  # m, m/s, rad
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


def random_profile(seed: int, duration: float = 90.0, depth0: float = 3.0) -> tuple:
    """A random maneuvering schedule in the form of :data:`PROFILE`, from ``seed`` alone.

    Drawn from ``numpy.random.default_rng(seed)`` (not from a run's stream: the same
    seed gives the same schedule in every run). Level first for U(5, 10) s at a
    speed U(1.2, 2.0) m/s; then, until ``duration``, a maneuver and a level run
    U(4, 12) s, each maneuver one of (equally likely)

    * ``dive`` / ``climb``: pitch U(8, 25) deg nose down / up for U(5, 12) s;
    * ``pitch steps``: 2-4 steps of alternating sign, U(5, 15) deg, U(2, 4) s each;

    and each segment a new commanded speed U(1.0, 2.2) m/s. A climb that would
    take the vehicle above 2 m, or a dive below 60 m (depth reckoned from the
    commands, v sin(pitch) times the segment's length), is turned the other way.
    The pitch is still rate-limited and lagged by :func:`trajectory`.
    """
    rng = np.random.default_rng(int(seed))
    u = rng.uniform
    t, depth = 0.0, float(depth0)
    first = u(5.0, 10.0)
    segs = [(0.0, first, 0.0, u(1.2, 2.0), "level")]
    t = first
    while t < duration:
        kind = ("dive", "climb", "pitch steps")[int(rng.integers(3))]
        if kind == "pitch steps":
            sign = 1.0 if rng.random() < 0.5 else -1.0
            for _ in range(int(rng.integers(2, 5))):
                d, p, v = u(2.0, 4.0), sign * u(5.0, 15.0), u(1.0, 2.2)
                segs.append((t, t + d, p, v, "pitch steps"))
                depth += v * np.sin(np.deg2rad(p)) * d
                t, sign = t + d, -sign
        else:
            d, p, v = u(5.0, 12.0), u(8.0, 25.0), u(1.0, 2.2)
            climb = kind == "climb"
            change = v * np.sin(np.deg2rad(p)) * d
            if (climb and depth - change < 2.0) or (not climb and depth + change > 60.0):
                climb = not climb
            segs.append((t, t + d, -p if climb else p, v, "climb" if climb else "dive"))
            depth += -change if climb else change
            t += d
        d = u(4.0, 12.0)
        segs.append((t, t + d, 0.0, u(1.0, 2.2), "level"))
        t += d
    return tuple((round(a, 6), round(b, 6), round(p, 6), round(v, 6), lab) for a, b, p, v, lab in segs)


def commands(t: np.ndarray, profile=PROFILE):
    """Commanded pitch (rad) and speed (m/s) at times ``t`` (level after the profile)."""
    pitch = np.zeros_like(t)
    speed = np.full_like(t, profile[-1][3])
    for t0, t1, p, v, _ in profile:
        sel = (t >= t0) & (t < t1)
        pitch[sel] = np.deg2rad(p)
        speed[sel] = v
    return pitch, speed


def maneuvers(duration: float, settle: float = 1.5, profile=PROFILE) -> list[list]:
    """[[t0, t1, label], ...]: segments with a non-zero pitch command, merged, plus settling."""
    out: list[list] = []
    for t0, t1, p, _, label in profile:
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


def trajectory(
    n: int,
    dt: float = T,
    depth0: float = 3.0,
    tau_pitch: float = 0.5,
    max_pitch_rate: float = 15.0,
    tau_speed: float = 2.0,
    profile=PROFILE,
) -> np.ndarray:
    """True states [depth, speed, pitch] (n, 3) at t = 0, dt, ..., following the profile."""
    t = dt * np.arange(n)
    pc, vc = commands(t, profile)
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


def sensor_rms(base=BASE_SIGMA, duration: float = 90.0, dt: float = T, regimes=REGIMES, drift: float = DRIFT):
    """Root-mean-square over the run of each sensor's sigma_c(t) with ``base_sigma`` = ``base``: the sensors'
    noise level as generated (the inverse of :func:`base_for_rms`). Its square, per sensor, is the measurement
    covariance R matched to the sensors' mean-square noise (paper 000's oracle R)."""
    t = dt * np.arange(int(round(duration / dt)))
    sigma = noise_sigma(t, duration, base, regimes, drift)
    return tuple(float(v) for v in np.sqrt(np.mean(sigma * sigma, axis=0)))


def base_for_rms(target, duration: float = 90.0, dt: float = T, regimes=REGIMES, drift: float = DRIFT) -> tuple:
    """``base_sigma`` whose sigma_c(t) has root-mean-square ``target[c]`` over the run.

    Used to put the sensors at the level of a filter's fixed R (R's std = the
    sensor's RMS noise, the regimes and drift varying around it).
    """
    t = dt * np.arange(int(round(duration / dt)))
    f = noise_sigma(t, duration, (1.0,), regimes, drift)[:, 0]
    rms = float(np.sqrt(np.mean(f * f)))
    return tuple(float(v) / rms if rms > 0 else 0.0 for v in np.asarray(target, float))


PARAMS = (
    Param("duration", float, 90.0, "length of the log", unit="s", low=0, low_open=True),
    Param("dt", float, T, "sample period", unit="s", low=0, low_open=True),
    Param("depth0", float, 3.0, "initial depth", unit="m"),
    Numbers(
        "base_sigma",
        list,
        BASE_SIGMA,
        "base noise standard deviations of the depth, speed and pitch sensors",
        unit="m, m/s, rad",
        length=3,
        low=0,
    ),
    Numbers(
        "noise_rms",
        list,
        None,
        "RMS over the run of each sensor's noise std (depth, speed, pitch), "
        "replacing base_sigma; regimes and drift vary around it (null: base_sigma)",
        unit="m, m/s, rad",
        length=3,
        low=0,
        optional=True,
    ),
    Numbers("regimes", list, REGIMES, "noise factor of each equal part of the run", low=0),
    Param("drift", float, DRIFT, "slow rise of the noise: factor 1 + drift t / duration", low=0),
    Param(
        "profile_seed",
        int,
        None,
        "seed of a random maneuvering schedule (random_profile); null: the fixed PROFILE",
        low=0,
        optional=True,
    ),
    Param("ref_every", int, 1, "reference at every ref_every-th sample", low=1),
    Intervals("ref_gaps", list, (), "[t0, t1) spans without reference", unit="s"),
)


@generator(PARAMS, record=True)
def make_frame(rng: np.random.Generator, p) -> Frame:
    """A synthetic lake-trial frame: sensors in ``channels``, truth in ``reference``."""
    n = int(round(p.duration / p.dt))
    t = p.dt * np.arange(n)
    profile = PROFILE if p.profile_seed is None else random_profile(p.profile_seed, p.duration, p.depth0)
    x = trajectory(n, p.dt, p.depth0, profile=profile)
    base_sigma = p.base_sigma
    if p.noise_rms is not None:
        base_sigma = base_for_rms(p.noise_rms, p.duration, p.dt, p.regimes, p.drift)
    sigma = noise_sigma(t, p.duration, base_sigma, p.regimes, p.drift)
    z = x + sigma * rng.standard_normal((n, 3))
    ref_ok = np.zeros(n, bool)
    ref_ok[:: p.ref_every] = True
    for t0, t1 in p.ref_gaps:
        ref_ok &= ~((t >= t0) & (t < t1))
    desc = {
        "depth": "depth gauge, positive down",
        "speed": "speed sensor, forward",
        "pitch": f"pitch sensor, {PITCH_CONVENTION}",
    }
    units = {"depth": ("m", "down"), "speed": ("m/s", "body forward"), "pitch": ("rad", "body")}
    channels, reference = {}, {}
    for i, name in enumerate(("depth", "speed", "pitch")):
        unit, frame = units[name]
        angles = (0,) if name == "pitch" else ()
        conv = PITCH_CONVENTION if name == "pitch" else ""
        channels[name] = Channel(z[:, i], unit, frame, None, (name,), angles, conv, desc[name])
        reference[name] = Channel(
            np.where(ref_ok, x[:, i], np.nan),
            unit,
            frame,
            ref_ok,
            (name,),
            angles,
            conv,
            f"true {name} (synthetic external reference)",
        )
    meta = {
        "source": "synthetic: replay.sim.lake_depth",
        "synthetic": True,
        "pitch_convention": PITCH_CONVENTION,
        "profile_seed": p.profile_seed,
        "profile": [list(seg) for seg in profile],
        "noise": {
            "base_sigma": list(base_sigma),
            "noise_rms": None if p.noise_rms is None else list(p.noise_rms),
            "regimes": list(p.regimes),
            "drift": p.drift,
        },
        "ref_every": int(p.ref_every),
        "ref_gaps": [list(g) for g in p.ref_gaps],
    }
    return Frame(
        t,
        channels,
        reference,
        None,
        meta,
        simulation=Simulation(dt=p.dt),
        maneuvers=tuple(tuple(m) for m in maneuvers(p.duration, profile=profile)),
    )


def write_example(path, rng: np.random.Generator, **params) -> Frame:
    """Write one synthetic lake-trial log (reference at half rate, one short and one long gap)."""
    # lazy: it imports pandas (0.55 s measured), for this file only
    from replay.adapters.lake_write import write  # noqa: PLC0415

    frame = make_frame(rng, **{**EXAMPLE, **params})
    write(
        frame,
        path,
        comments=[
            "SYNTHETIC: generated by replay.sim.lake_depth (`replay datasets make sim/lake-depth`), not a lake trial",
            "synthetic: true",
            f"convention: depth positive down; {PITCH_CONVENTION}",
            "maneuvers: " + "; ".join(f"{a:g}-{b:g} {lab}" for a, b, lab in frame.maneuvers),
        ],
    )
    return frame
