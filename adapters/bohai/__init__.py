"""Bohai AUV navigation CSV adapter (``bohai-csv``).

Reads the CSV logs of Wang et al., "Underwater AUV navigation dataset in
natural scenarios", Electronics 12(18):3788 (2023), CC0, in either header
layout (see the README beside the data, ``datasets/bohai/README.md`` in the
shared data directory):

* 36 columns: ``lat_gps, lon_gps, alt_gps, roll, ..., lat, lon, depth, height,
  time, time_gps`` (GPS fix columns apart from the navigation solution);
* 31 columns: ``lat, lon, alt, roll, ..., orimode, time``.

What the returned :class:`~replay.frame.Frame` holds:

* ``t``: ``time - time[0]`` (s); ``epoch`` is None (no trusted date in the
  files). A ``time`` column in milliseconds (or micro-, nanoseconds) is
  recognised from its median step and the position-derived speed, converted,
  and counted as "repaired" (``meta["time_unit"]``); a step that fits no unit
  is refused (:mod:`.cells`). A ``time_gps`` column that decodes as a GPS
  time of day (hhmmss) is
  recorded in ``meta["gps_time_of_day"]``, nothing more.
* ``reference["position"]``: (n, 2) east/north in m, local ENU = UTM - origin,
  from the navigation solution ``lat``/``lon``. Masked where lat/lon is
  missing or impossible, where fresh GPS fixes contradict it (see
  :func:`gps_contradiction`) and at the jumps of the navigation solution (see
  :func:`mask_jumps`). The navigation solution is dead reckoning between GPS
  corrections: unmasked samples in a dive still carry its drift.
* ``channels``: ``attitude`` (roll, pitch, yaw), ``gyro`` (wx, wy, wz),
  ``gps_position`` and ``gps_alt`` (36 columns) or ``alt`` (31 columns), and
  every other column that passes the plausibility checks (named after the
  column). A column that fails is not passed on: ``frame.report`` holds a
  "dropped" entry with the finding and ``meta["dropped_columns"]`` maps the
  column to the same reason. ``inf`` cells are missing values, and a few cells
  beyond their kind's magnitude limit (at most 1 % of the column) are masked:
  both counted per column, neither drops the column.
* ``Frame.roles`` (:class:`replay.roles.SensorInput` records): what tasks may use the channels for
  (:func:`replay.tasks.role_input`): ``gps`` = ``gps_position``; ``velocity`` =
  ``vf`` (a body forward velocity, as a DVL's) when it follows the track's speed along
  the heading (``meta["forward_velocity"]``: correlation, median difference; the
  31-column files; the 36-column files' ``vf`` fails the magnitude check); ``imu`` =
  ``gyro`` when its wz follows the yaw rate. ``Frame.columns`` maps
  a channel to its columns, so that a task lacking a channel can name the
  report line that removed it.
* ``meta``: source, sha256, layout, adapter, crs, epsg, origin, rows, time,
  jumps, speed, yaw_course, gyro_attitude, forward_velocity, dropped_columns; gps (36 columns);
  gps_time_of_day when ``time_gps`` holds one.

Bad input raises :class:`~replay.util.errors.DataError` with one line naming the
file and, where it applies, the file line (header = line 1).

Modules: :mod:`.loader` (:func:`load`: the frame from the checked parts),
:mod:`.reading` (bytes, table, layout, rows, time axis), :mod:`.cells`
(infinite and isolated out-of-limit cells, the time unit), :mod:`.columns` (the
two layouts, what each column is, the per-column plausibility checks),
:mod:`.reference` (jumps of the navigation solution, GPS contradictions),
:mod:`.gps` (fresh fixes, stale values, time of day), :mod:`.checks` (track
velocity, yaw against course, gyro against attitude); the UTM projection is
:mod:`replay.adapters.geodesy`, shared with the ``bags`` adapter.
"""

from replay.adapters.geodesy import utm_epsg

from .checks import track_velocity
from .columns import (
    ACCURACY_LIMITS,
    COLS31,
    COLS36,
    COLUMNS,
    GROUPS,
    LIMITS,
    PRIORITY,
    check_agreement,
    check_columns,
    check_constant,
    check_integer,
    check_limit,
    check_nonnegative,
    find_duplicate,
)
from .gps import fresh_mask, stale_stretches
from .loader import load
from .reference import NOMINAL_STEP, find_jumps, gps_contradiction, mask_jumps

__all__ = [
    "ACCURACY_LIMITS",
    "COLS31",
    "COLS36",
    "COLUMNS",
    "GROUPS",
    "LIMITS",
    "NOMINAL_STEP",
    "PRIORITY",
    "check_agreement",
    "check_columns",
    "check_constant",
    "check_integer",
    "check_limit",
    "check_nonnegative",
    "find_duplicate",
    "find_jumps",
    "fresh_mask",
    "gps_contradiction",
    "load",
    "mask_jumps",
    "stale_stretches",
    "track_velocity",
    "utm_epsg",
]
