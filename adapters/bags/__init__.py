"""ROS bags and MCAP files (``bags`` adapter): ROS 1 ``.bag``, ROS 2 bag
directories (sqlite3 or MCAP storage), standalone ``.mcap`` (ROS 2 CDR, Foxglove
JSON or protobuf channels).

Which topic feeds which channel comes from a mapping (:mod:`.mapping`, a TOML
file or a dict); without one, :func:`replay.adapters.mapping_propose.propose` picks the obvious one.
Messages become arrays by :mod:`.rosmsg`.

**One time axis.** ``t`` is the sorted union of the stamps of every mapped
topic (``header.stamp`` by default, the bag's log time with ``time = "log"``).
Each channel holds its topic's values at that topic's own stamps and is *not
valid* at every other sample (values NaN there): no sample is interpolated or
invented. Stamps shared by several topics are one sample. ``frame.report`` says
how many samples each topic fills. The other time of every message is kept as
the channel ``<name>_log_time`` (or ``<name>_header_time``), seconds on the
same origin as ``t``. ``meta["t0_ns"]`` is the absolute stamp of ``t = 0``.

**Simulation time.** Stamps before 1980 (``use_sim_time`` recordings, which
start near 0 s) give ``epoch = None`` and ``meta["sim_time"] = True``.

**Geodetic data.** NavSatFix positions are projected to the WGS 84 UTM zone of
the first mapped fix topic (median longitude) and expressed as local ENU
relative to its first valid fix: ``meta["crs"]``, ``meta["origin"]`` (easting,
northing) and ``meta["origin_alt"]``. Fixes with ``status < 0`` (NO_FIX) or
impossible coordinates are masked and counted.

**Bad input** raises :class:`~replay.util.errors.DataError` with one line naming the
file and topic: a missing topic, a topic of an unsupported or unexpected type,
no messages on a mapped topic, non-increasing stamps on a topic, a truncated or
corrupted file. After a truncation, the messages before it are used only with
``allow_truncated = true`` and the frame report then flags the recording as
truncated (``meta["truncated"]``).

Modules: :mod:`.recording` (what was read), :mod:`.reading` (ROS 1 / ROS 2
bags through rosbags, and the dispatch by kind), :mod:`.mcap_reader`
(standalone MCAP: CDR, Foxglove JSON and protobuf channels), :mod:`.loader`
(:func:`load`, :func:`build_frame`, :func:`inspect`), :mod:`.writer` (a ROS 2
bag writer, the inverse used by the exports and the simulated bags); the
projection is :mod:`replay.adapters.geodesy`, shared with ``bohai-csv``.
"""

from replay.adapters.geodesy import Geo, enu_to_geodetic, utm_epsg

from .loader import SIM_TIME_BEFORE_NS, build_frame, inspect, load, resolve_mapping
from .reading import read, recording_kind
from .recording import Recording, Topic
from .writer import BagOut

__all__ = [
    "SIM_TIME_BEFORE_NS",
    "BagOut",
    "Geo",
    "Recording",
    "Topic",
    "build_frame",
    "enu_to_geodetic",
    "inspect",
    "load",
    "read",
    "recording_kind",
    "resolve_mapping",
    "utm_epsg",
]
