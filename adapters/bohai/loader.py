"""``load``: one Bohai CSV log into a :class:`~replay.frame.Frame` (see the package docstring)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyproj

from replay.adapters.options import declare
from replay.adapters.geodesy import plausible_latlon, project, utm_epsg
from replay.frame import Channel, Frame, Report
from replay.roles import SensorInput
from replay.util.errors import DataError
from replay.util.params import Param
from replay.util.progress import load_stage

from .cells import mask_infinite, mask_isolated, time_unit
from .checks import _forward_check, _gyro_check, _speed_check, _yaw_check, track_velocity
from .columns import COLS31, COLS36, COLUMNS, GROUPS, check_columns
from .gps import _fresh_alt, _gps_fixes, _time_of_day
from .reading import _clean_rows, _drop, _layout, _read, _rows, _time_axis
from .reference import _reference_mask


@declare(
    "bohai-csv",
    Param(
        "jump_threshold",
        float,
        5.0,
        "a step of the navigation solution longer than this is a jump",
        unit="m per 0.1 s",
        low=0.0,
        low_open=True,
    ),
    Param("max_speed", float, 10.0, "the fastest plausible motion of the vehicle", unit="m/s", low=0.0, low_open=True),
    Param(
        "gps_tolerance",
        float,
        15.0,
        "how far a fresh GPS fix may lie from the navigation solution before it contradicts it (null: no GPS check)",
        unit="m",
        low=0.0,
        low_open=True,
        optional=True,
    ),
    Param(
        "gap_factor",
        float,
        5.0,
        "a time step longer than this many median steps is flagged as a gap",
        low=1.0,
        low_open=True,
    ),
)
def load(path, *, jump_threshold, max_speed, gps_tolerance, gap_factor) -> Frame:
    """Read one Bohai CSV log into a :class:`Frame`."""
    path = Path(path)
    load_stage("reading the table", 0.0)
    table, lines, sha256 = _read(path)
    load_stage("checking the cells", 0.3)
    layout = _layout(path, list(table.columns))
    report = Report()
    mask_infinite(table, lines, report)
    meta = {"source": str(path), "sha256": sha256, "layout": layout, "adapter": "bohai-csv", "dropped_columns": {}}
    names = COLS36 if layout == 36 else COLS31
    for c in table.columns:
        if c not in names:
            _drop(report, meta, c, len(table), f"not a column of the {layout}-column layout")
    cols, lines = _clean_rows(path, table, names, lines, report, meta)
    del table
    time = time_unit(path, cols["time"], cols, lines, report, meta, max_speed)
    mask_isolated(cols, lines, report)
    t = time - time[0]
    meta["time"] = _time_axis(t, lines, report, gap_factor)
    meta["time"]["offset"] = float(time[0])

    # projection, GPS fixes, reference position
    lat, lon = cols["lat"], cols["lon"]
    geo_ok = plausible_latlon(lat, lon)
    if not geo_ok.any():
        raise DataError(path, "no plausible lat/lon in the navigation solution")
    if (~geo_ok).any():
        report.add(
            "masked", "position", int((~geo_ok).sum()), f"lat/lon missing or impossible at {_rows(lines, ~geo_ok)}"
        )
    load_stage("projecting and checking the GPS fixes", 0.45)
    epsg = utm_epsg(lat[geo_ok], lon[geo_ok])
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", epsg, always_xy=True)
    utm = project(to_utm, lat, lon, geo_ok)
    gps = _gps_fixes(cols, t, to_utm, lines, report, meta, jump_threshold, max_speed) if layout == 36 else None
    load_stage("masking the jumps of the navigation solution", 0.55)
    valid = _reference_mask(t, utm, geo_ok, gps, lines, report, meta, jump_threshold, max_speed, gps_tolerance)
    origin = utm[int(np.argmax(valid if valid.any() else geo_ok))].copy()
    meta.update(crs=f"EPSG:{epsg}", epsg=epsg, origin=[float(origin[0]), float(origin[1])])
    pos = utm - origin
    reference = {
        "position": Channel(
            pos,
            "m",
            "ENU local",
            valid,
            ("east", "north"),
            description="navigation solution lat/lon in UTM minus origin; masked where displaced (see meta['jumps'])",
        )
    }
    meta["reference_provenance"] = {  # issue 35: printed on every table (replay/scoring/provenance.py)
        "kind": "onboard solution",
        "source": "the vehicle's navigation solution (lat/lon): its GPS on the surface, its own dead reckoning "
        "after a dive",
        "built_from": {"gps_position": "the navigation solution is built from the GPS fixes on the surface"},
    }
    vel = track_velocity(t, pos, valid)
    meta["speed"] = _speed_check(vel, report)

    load_stage("checking the sensor columns", 0.7)
    channels = _sensor_channels(cols, t, vel, lines, report, meta)
    if gps is not None:
        channels["gps_position"] = Channel(
            gps["utm"] - origin,
            "m",
            "ENU local",
            gps["valid"],
            ("east", "north"),
            description="GPS fix lat_gps/lon_gps in UTM minus origin; valid only where a new fix appears",
        )
    if layout == 36:
        _time_of_day(cols["time_gps"], t, report, meta)
    columns = {  # the channels made of several columns (for a missing input's reason: the report names columns)
        "attitude": ("roll", "pitch", "yaw"),
        "gyro": ("wx", "wy", "wz"),
        "gps_position": ("lat_gps", "lon_gps"),
        "gps_alt": ("alt_gps",),
    }
    return Frame(t, channels, reference, None, meta, report, roles=_roles(channels, meta), columns=columns)


def _roles(channels, meta) -> tuple:
    """What tasks may use the channels for (replay.tasks.role_input): the GPS fixes, the forward
    velocity ``vf`` (a body velocity, as a DVL's) when it follows the track's speed along the
    heading (the 31-column files; the 36-column files' ``vf`` holds no velocity and is dropped), and
    the gyro as an IMU when its wz follows the yaw rate (the adapter's gyro check)."""
    found = []
    if "gps_position" in channels:
        found.append(SensorInput("gps", "gps_position", "columns lat_gps, lon_gps", {"position": "gps_position"}))
    if "vf" in channels:  # checked against the track (_forward_check): the forward speed, as a DVL's
        found.append(SensorInput("velocity", "vf", "column vf", {"velocity": "vf"}))
    imu = {}
    if "gyro" in channels and meta.get("gyro_attitude", {}).get("wz_yaw", 0.0) >= 0.3:
        imu["gyro"] = "gyro"
    if "attitude" in channels:  # the AHRS attitude (roll, pitch, yaw in the frame's ENU convention)
        imu["attitude"] = "attitude"
    if imu:
        # its yaw is east-north-up when it follows the course over ground (the adapter's yaw check)
        enu = meta.get("yaw_course", {}).get("median_abs_rad", np.inf) < 0.5
        source = "columns " + ", ".join(COLUMNS_OF[f] for f in imu)
        entry = "gyro" if "gyro" in imu else "attitude"
        found.append(SensorInput("imu", entry, source, imu, attitude_enu=bool(enu)))
    return tuple(found)


COLUMNS_OF = {"gyro": "wx, wy, wz", "attitude": "roll, pitch, yaw"}


def _sensor_channels(cols, t, vel, lines, report, meta) -> dict:
    """Channels from the columns that pass the plausibility checks."""
    n = len(t)
    channels = {}
    for c, found in check_columns(cols, vel).items():
        if found:
            _drop(report, meta, c, n, "; ".join(found))
    passed = [c for c in cols if c in COLUMNS and c not in meta["dropped_columns"]]
    for name, (members, comps, angles, convention) in GROUPS.items():
        if all(c in passed for c in members):
            values = np.column_stack([cols[c] for c in members])
            frame = "body" if name == "attitude" else COLUMNS[members[0]][2]
            channels[name] = Channel(
                values,
                COLUMNS[members[0]][1],
                frame,
                None,
                comps,
                angles,
                convention,
                ", ".join(COLUMNS[c][3] for c in members),
            )
            passed = [c for c in passed if c not in members]
    if "attitude" in channels:
        meta["yaw_course"] = _yaw_check(channels["attitude"].values[:, 2], vel, report)
    if "attitude" in channels and "gyro" in channels:
        meta["gyro_attitude"] = _gyro_check(t, channels["gyro"].values, channels["attitude"].values, report)
    if "vf" in passed:  # a body forward velocity (a DVL's) when it follows the track's speed
        if "attitude" in channels:
            meta["forward_velocity"], found = _forward_check(cols["vf"], channels["attitude"].values[:, 2], vel, report)
        else:
            found = "no attitude to compare it with the track's speed along the heading"
        if found:
            _drop(report, meta, "vf", n, found)
            passed.remove("vf")
    for c in passed:
        kind, unit, frame, desc = COLUMNS[c]
        if kind == "altitude":
            name = "gps_alt" if c == "alt_gps" else c
            channels[name] = _fresh_alt(cols[c], t, lines, name, report)
            continue
        angles = (0,) if kind in ("roll", "pitch", "yaw") else ()
        channels[c] = Channel(cols[c], unit, frame, None, (c,), angles, "", desc)
    for name, ch in channels.items():
        bad = ~np.isfinite(ch.values.reshape(n, -1)).all(axis=1)
        if bad.any() and name not in ("gps_alt", "alt"):
            report.add("masked", name, int(bad.sum()), f"missing values at {_rows(lines, bad)}")
    return channels
