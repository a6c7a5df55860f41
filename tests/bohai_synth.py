"""Generated Bohai CSV logs (both header layouts) with a known track: a vehicle at about 2 m/s on
a winding course at 10 Hz, the navigation solution exact, and a forward velocity column."""
from __future__ import annotations

import numpy as np
import pyproj

from replay.adapters.bohai import COLS31, COLS36

EPSG = 32651  # UTM 51N, the Bohai Sea
E0, N0 = 500000.0, 4505000.0


def track(seconds=300.0, rate=10.0):
    """(t, east, north, yaw, speed, yaw rate) of the generated course."""
    t = np.arange(0, seconds, 1 / rate)
    r = 0.05 * np.sin(2 * np.pi * t / 120)  # yaw rate, rad/s
    speed = 2.0 + 0.3 * np.sin(2 * np.pi * t / 90)
    yaw = 0.3 + np.cumsum(r) / rate
    east = E0 + np.cumsum(speed * np.cos(yaw)) / rate
    north = N0 + np.cumsum(speed * np.sin(yaw)) / rate
    return t, east, north, yaw, speed, r


def write(path, layout: int, forward: str = "real", seed: int = 0, seconds=300.0, dives=()):
    """A generated log at ``path``. ``forward``: "real" (the speed plus N(0.006, 0.03) m/s),
    "noise" (a column unrelated to the motion, within the limits) or "garbage" (the 36-column
    files' vf: |value| up to 80). ``dives``: ``[(t0, t1), ...]`` s, spans in which the 36-column
    layout's GPS columns hold the last fix (no fix under water)."""
    g = np.random.default_rng(seed)
    t, east, north, yaw, speed, r = track(seconds)
    n = len(t)
    lon, lat = pyproj.Transformer.from_crs(f"EPSG:{EPSG}", "EPSG:4326", always_xy=True).transform(east, north)
    small = lambda s=0.01: g.normal(0, s, n)  # noqa: E731
    vf = {
        "real": speed + 0.006 + small(0.03),
        "noise": g.uniform(-3, 3, n),
        "garbage": np.abs(g.normal(0, 20, n)).clip(max=80),
    }[forward]
    cols = {
        "roll": small(), "pitch": small(), "yaw": yaw - 2 * np.pi * np.round(yaw / (2 * np.pi)),
        "vn": speed * np.sin(yaw) + small(), "ve": speed * np.cos(yaw) + small(), "vf": vf,
        "vl": small(0.05), "vu": small(0.05), "ax": small(0.1), "ay": small(0.1), "az": 9.8 + small(0.1),
        "af": small(0.1), "al": small(0.1), "au": small(0.1), "wx": small(0.002), "wy": small(0.002),
        "wz": r + small(0.002), "wf": small(0.002), "wl": small(0.002), "wu": small(0.002),
        "pos_accuracy": 0.5 + np.abs(small(0.1)), "vel_accuracy": 0.05 + np.abs(small(0.01)),
        "navstat": np.full(n, 4.0), "numsats": np.full(n, 12.0), "posmode": np.full(n, 4.0),
        "velmode": np.full(n, 4.0), "orimode": np.full(n, 4.0), "time": t,
        "lat": lat, "lon": lon, "alt": np.full(n, 0.5),
    }
    if layout == 36:
        fix = (np.arange(n) // 10) * 10  # a fix per second, held between
        for t0, t1 in dives:  # under water: the last fix before the dive, held
            under = (t >= t0) & (t < t1)
            fix[under] = fix[np.flatnonzero(under)[0] - 1]
        cols.update(lat_gps=lat[fix] + 2e-6 * g.standard_normal(n)[fix], lon_gps=lon[fix], alt_gps=np.full(n, 0.5),
                    depth=np.zeros(n), height=small(1.0) ** 2, time_gps=np.zeros(n))
    names = COLS36 if layout == 36 else COLS31
    table = np.column_stack([cols[c] for c in names])
    with open(path, "w") as fh:
        fh.write(",".join(names) + "\n")
        for row in table:
            fh.write(",".join(f"{v:.10g}" for v in row) + "\n")
    return path
