"""Hostile inputs to the adapters and the tasks (issue 12): each a one-line refusal or a counted repair.

Bohai-style CSVs are the first 400 rows of a real log (``20220822_0_6``) edited in
``tmp_path`` (quirks listed in the data's README: time unit, infinite and spiking
cells, duplicate and backward times, dropped columns); lake-trial logs come from
the ``sim/lake-depth`` generator, written by the lake writer and edited; bags are
tiny ROS 2 bags (MCAP storage) written here. Every case goes through the CLI
(``tests/hostile.py``): a refusal is exit 2 with one stderr line naming the file,
row, topic or parameter; a repair is exit 0 with the count in the manifest's
``adapter_report``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hostile import assert_ok, assert_refused, register
from replay.adapters.bags.writer import BagOut

ROWS = 400
T0 = 1_700_000_000 * 10**9  # ns: a 2023 stamp
M_PER_DEG_LON = 111_320.0 * np.cos(np.deg2rad(42.0))


# ---------------------------------------------------------------- builders

@pytest.fixture(scope="module")
def bohai_head(bohai_dir) -> pd.DataFrame:
    """The first 400 rows of a real Bohai log (36-column layout)."""
    return pd.read_csv(bohai_dir / "20220822_0_6.csv", nrows=ROWS)


@pytest.fixture(scope="module")
def lake_text(tmp_path_factory) -> str:
    """A synthetic lake-trial log (1800 rows at 20 Hz) as written by the lake writer."""
    from replay.data import registry
    from replay.adapters.lake_write import write

    path = tmp_path_factory.mktemp("lake") / "lake.csv"
    write(registry.load_frame("sim/lake-depth", rng=0), path)
    return path.read_text()


def make_bag(path: Path, fix_stamps=None, nan_fix=(), extra_fix=False, empty=False) -> Path:
    """A 40 s ROS 2 bag: /fix NavSatFix at 1 Hz (east at 1 m/s), /wheel Odometry and /imu Imu at
    10 Hz, /empty Imu without messages (and /fix2, a copy of /fix, with ``extra_fix``)."""
    out = BagOut(path)
    T = out.T
    fix = out.connection("/fix", "sensor_msgs/msg/NavSatFix")
    fix2 = out.connection("/fix2", "sensor_msgs/msg/NavSatFix") if extra_fix else None
    wheel = out.connection("/wheel", "nav_msgs/msg/Odometry")
    imu = out.connection("/imu", "sensor_msgs/msg/Imu")
    out.connection("/empty", "sensor_msgs/msg/Imu")
    if empty:
        out.close()
        return path
    stamps = list(fix_stamps) if fix_stamps is not None else [T0 + k * 10**9 for k in range(40)]
    for k, s in enumerate(stamps):
        lat = np.nan if k in nan_fix else 42.0
        msg = T["sensor_msgs/msg/NavSatFix"](
            header=out.header(s, "gps"), status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
            latitude=lat, longitude=-71.0 + k / M_PER_DEG_LON, altitude=5.0,
            position_covariance=np.zeros(9), position_covariance_type=0)
        for c in (fix, fix2) if fix2 else (fix,):
            out.write(c, T0 + k * 10**9 + 1000, msg)  # log times increase; header stamps are ``s``
    q0, z3 = (0.0, 0.0, 0.0, 1.0), np.zeros(3)
    for k in range(400):
        s = T0 + k * 10**8
        out.write(wheel, s, out.odometry(s, "odom", "base", (k / 10, 0, 0), q0, (1.0, 0, 0), z3))
        out.write(imu, s, T["sensor_msgs/msg/Imu"](
            header=out.header(s, "imu"), orientation=out.quat(q0), orientation_covariance=np.zeros(9),
            angular_velocity=out.vec(z3), angular_velocity_covariance=np.zeros(9),
            linear_acceleration=out.vec(z3), linear_acceleration_covariance=np.zeros(9)))
    out.close()
    return path


GOOD_MAP = '[channels]\ngps = "/fix"\nwheel = "/wheel"\nimu = "/imu"\n[reference]\nposition = "/fix"\n'


def report_count(out: Path, action: str, what: str, text: str = "") -> int:
    """Summed count of the manifest's adapter-report entries matching action, what and text."""
    report = json.loads((out / "manifest.json").read_text())["adapter_report"]
    return sum(e["count"] for e in report if e["action"] == action and e["what"] == what and text in e["reason"])


# ---------------------------------------------------------------- Bohai-style CSV

def _set(col, rows, value):
    def edit(t):
        if isinstance(value, str):
            t[col] = t[col].astype(object)
        t.loc[list(rows), col] = value
        return t
    return edit


def _scale_time(factor):
    def edit(t):
        t["time"] = t["time"] * factor
        return t
    return edit


def _time_at(i, value_of):
    def edit(t):
        t.loc[i, "time"] = value_of(t)
        return t
    return edit


BOHAI_REFUSED = [  # id, edit of the table (or of the text lines), task, message
    ("bohai-time-backwards", _time_at(101, lambda t: t.loc[99, "time"]), "position",
     r"row 103: time decreases from"),
    ("bohai-duplicate-time", _time_at(101, lambda t: t.loc[100, "time"]), "position",
     r"row 103: time [\d.]+ s repeats line 102 with different values"),
    ("bohai-time-centiseconds", _scale_time(100), "position",
     r"column time: median step 10\.2 is implausible for a ~10 Hz log"),
    ("bohai-time-picoseconds", _scale_time(1e12), "position", r"column time: median step 1\.02e\+11"),
    ("bohai-non-numeric", _set("roll", [50], "abc"), "position", r"row 52: non-numeric value 'abc' in column roll"),
    ("bohai-no-lat", lambda t: t.drop(columns=["lat"]), "position", r"missing columns lat "),
    ("bohai-lat-all-nan", _set("lat", range(ROWS), np.nan), "position", r"no plausible lat/lon"),
    ("bohai-header-only", lambda t: t.iloc[:0], "position", r"header only, no data rows"),
    ("bohai-roll-zero-dead-reckoning", _set("roll", range(ROWS), 0.0), "dead-reckoning",
     r"task dead-reckoning needs an attitude channel .*: the adapter dropped roll \(400 samples: all zero\)"),
    ("bohai-no-gps-gps-odom", lambda t: _set("lon_gps", range(ROWS), 0.0)(_set("lat_gps", range(ROWS), 0.0)(t)),
     "gps-odom", r"task gps-odom needs a gps input .*: the adapter dropped lat_gps \(400 samples: all zero\)"),
    ("bohai-repeated-header-name", lambda t: t.rename(columns={"height": "lat"}), "position",
     r"row 1: column 'lat' appears twice in the header"),  # pandas would read the second as lat.1
]

BOHAI_REPAIRED = [  # id, edit, (action, what, reason text, count)
    ("bohai-time-milliseconds", _scale_time(1e3), ("repaired", "time", "in milliseconds", ROWS)),
    ("bohai-time-microseconds", _scale_time(1e6), ("repaired", "time", "in microseconds", ROWS)),
    ("bohai-inf-roll", _set("roll", range(100, 150), np.inf), ("masked", "roll", "infinite values", 50)),
    ("bohai-inf-lat", _set("lat", range(100, 150), -np.inf), ("masked", "position", "lat/lon missing", 50)),
    ("bohai-spikes-wz", _set("wz", [10, 20, 30], 1e30), ("masked", "wz", "beyond the 10 rad/s limit", 3)),
    ("bohai-duplicate-row", lambda t: pd.concat([t.iloc[:60], t.iloc[59:]]).reset_index(drop=True),
     ("dropped", "rows", "exact duplicates", 1)),
    ("bohai-nan-time", _set("time", [30, 31, 32], np.nan), ("dropped", "rows", "no time value", 3)),
]

register(*(c[0] for c in BOHAI_REFUSED), *(c[0] for c in BOHAI_REPAIRED), "bohai-ragged-row", "bohai-blank-rows")


def write_table(path: Path, table: pd.DataFrame) -> Path:
    table.to_csv(path, index=False)
    return path


@pytest.mark.parametrize("case,edit,task,match", BOHAI_REFUSED, ids=[c[0] for c in BOHAI_REFUSED])
def test_bohai_refused(bohai_head, tmp_path, case, edit, task, match):
    path = write_table(tmp_path / "log.csv", edit(bohai_head.copy()))
    line = assert_refused(["eval", path, "--task", task, "-f", "ekf", "--out", tmp_path / "o"], match)
    assert str(path) in line


@pytest.mark.parametrize("case,edit,expect", BOHAI_REPAIRED, ids=[c[0] for c in BOHAI_REPAIRED])
def test_bohai_repaired(bohai_head, tmp_path, case, edit, expect):
    path = write_table(tmp_path / "log.csv", edit(bohai_head.copy()))
    assert_ok(["eval", path, "--task", "position", "-f", "ekf", "--out", tmp_path / "o"])
    action, what, text, count = expect
    assert report_count(tmp_path / "o", action, what, text) == count


def test_bohai_ragged_row_and_blank_rows(bohai_head, tmp_path):
    lines = bohai_head.to_csv(index=False).splitlines()
    ragged = tmp_path / "ragged.csv"
    ragged.write_text("\n".join(lines[:40] + [lines[40] + ",1,2"] + lines[41:]) + "\n")
    assert_refused(["eval", ragged, "-f", "ekf", "--out", tmp_path / "o"], r"row 41: not a readable CSV table")
    blank = tmp_path / "blank.csv"
    blank.write_text("\n".join(lines[:40] + ["", ""] + lines[40:]) + "\n")
    assert_ok(["eval", blank, "--task", "position", "-f", "ekf", "--out", tmp_path / "b"])
    assert report_count(tmp_path / "b", "dropped", "rows", "empty or all-NaN rows at lines 41, 42") == 2


# ---------------------------------------------------------------- lake-trial logs

def _lake(text: str, header=None, row_edit=None) -> str:
    lines = text.splitlines()
    first = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    head, body = lines[:first], lines[first + 1:]
    cols = lines[first] if header is None else header(lines[first])
    if row_edit is not None:
        body = [",".join(row_edit(i, ln.split(","))) for i, ln in enumerate(body)]
    return "\n".join(head + [cols] + body) + "\n"


def _cell(j, value, every=None, rows=()):
    def edit(i, cells):
        if (every and i % every == 5) or i in rows:
            cells[j] = value(cells[j])
        return cells
    return edit


def _column(j, value):
    def edit(i, cells):
        cells[j] = f"{value(float(cells[j])):.10g}" if cells[j].strip() else cells[j]
        return cells
    return edit


LAKE_REFUSED = [
    ("lake-time-ms-named-s", dict(row_edit=lambda i, c: [f"{float(c[0]) * 1000:g}"] + c[1:]),
     r"column time_s: median time step 50 s is implausible .*milliseconds \(name it time_ms\)"),
    ("lake-time-s-named-ms", dict(header=lambda h: h.replace("time_s", "time_ms")),
     r"column time_ms: median time step 5e-05 s is implausible .*seconds \(name it time_s\)"),
    ("lake-degrees-named-rad", dict(header=lambda h: h.replace("pitch_deg", "pitch_rad")),
     r"column pitch_rad: values reach .* the column looks like degrees"),
    ("lake-no-time-column", dict(header=lambda h: h.replace("time_s", "clock_s")), r"no time column"),
    ("lake-unknown-unit", dict(header=lambda h: h.replace("depth_m,", "depth_ft,")),
     r"column depth_ft: unit 'ft' not recognised for depth"),
    ("lake-non-numeric", dict(row_edit=_cell(1, lambda v: "deep", rows=(10,))),
     r"row 13: column depth_m: non-numeric value 'deep'"),
    # issue 23: units checked against the values (depth against speed x sin(pitch), sensor against reference)
    ("lake-depths-m-named-cm", dict(header=lambda h: h.replace("depth_m", "depth_cm")),
     r"column depth_cm: depth changes are 0\.01 x what speed_mps and pitch_deg imply .*not in cm "
     r"\(it looks like m\)$"),
    ("lake-ref-depth-m-named-mm", dict(header=lambda h: h.replace("ref_depth_m", "ref_depth_mm")),
     r"column ref_depth_mm: depth changes are 0\.001 x .*\(it looks like m\)$"),
    ("lake-speed-m-named-cm", dict(header=lambda h: h.replace("speed_mps,pitch", "speed_cmps,pitch")),
     r"column speed_cmps: ref_speed_mps is [\d.]+ x speed_cmps .*not in cmps \(it looks like m/s\)"),
    ("lake-ref-speed-m-named-kn", dict(header=lambda h: h.replace("ref_speed_mps", "ref_speed_cmps")),
     r"column ref_speed_cmps: .*\(it looks like m/s\)"),
    ("lake-speed-cm-named-m", dict(row_edit=_column(2, lambda v: v * 100)),
     r"column speed_mps: 1800 of 1800 values are outside the plausible speed range .*the values fit cm/s"),
    ("lake-ref-pitch-rad-named-deg", dict(row_edit=_column(6, np.deg2rad)),
     r"columns pitch_deg and ref_pitch_deg: ref_pitch_deg is 0\.01\d+ x pitch_deg .*units of the two disagree"),
]
LAKE_REPAIRED = [
    ("lake-inf-depth", _cell(1, lambda v: "inf", every=30), ("masked", "depth_m", "infinite values", 60)),
    ("lake-rows-without-time", _cell(0, lambda v: "", every=100), ("dropped", "rows", "without a time", 18)),
    ("lake-time-backwards", _cell(0, lambda v: "0.001", rows=(500,)), ("dropped", "time_s", "not increasing", 1)),
    ("lake-depth-out-of-range", _cell(1, lambda v: "99999", every=450), ("masked", "depth_m", "plausible", 4)),
]
register(*(c[0] for c in LAKE_REFUSED), *(c[0] for c in LAKE_REPAIRED))


@pytest.mark.parametrize("case,edits,match", LAKE_REFUSED, ids=[c[0] for c in LAKE_REFUSED])
def test_lake_refused(lake_text, tmp_path, case, edits, match):
    path = tmp_path / "lake.csv"
    path.write_text(_lake(lake_text, **edits))
    line = assert_refused(["eval", path, "--adapter", "lake", "-f", "ekf", "--out", tmp_path / "o"], match)
    assert str(path) in line


@pytest.mark.parametrize("case,row_edit,expect", LAKE_REPAIRED, ids=[c[0] for c in LAKE_REPAIRED])
def test_lake_repaired(lake_text, tmp_path, case, row_edit, expect):
    path = tmp_path / "lake.csv"
    path.write_text(_lake(lake_text, row_edit=row_edit))
    assert_ok(["eval", path, "--adapter", "lake", "-f", "ekf", "--out", tmp_path / "o"])
    action, what, text, count = expect
    assert report_count(tmp_path / "o", action, what, text) == count


# ---------------------------------------------------------------- bags, MCAP, mappings

def _mcap_of(bag: Path) -> Path:
    return next(bag.glob("*.mcap"))


BAG_REFUSED = [  # id, how to make the input ((tmp_path, base bag) -> path), mapping text or None, task, message
    ("mcap-truncated", lambda d, base: _cut(_mcap_of(base), d / "t.mcap", 0.5), GOOD_MAP, "gps-odom",
     r"t\.mcap: truncated or corrupted"),
    ("mcap-wrong-magic", lambda d, base: _write(d / "x.mcap", b"\x89HDF\r\n\x1a\n" + bytes(200)), None, None,
     r"x\.mcap: truncated or corrupted, no channel could be read .*invalid magic"),
    ("mcap-empty-file", lambda d, base: _write(d / "e.mcap", b""), None, None, r"e\.mcap: empty file \(0 bytes\)"),
    ("bag-without-messages", lambda d, base: make_bag(d / "b", empty=True), None, None,
     r"no topic of a supported type to map"),
    ("mapping-toml-syntax", lambda d, base: base, '[channels\ngps = "/fix"\n', None,
     r"m\.toml: not valid TOML: .*line 1"),
    ("mapping-unknown-key", lambda d, base: base, "topics = 1\n" + GOOD_MAP, None,
     r"m\.toml: topics: unknown key \(known: allow_truncated, channels, "),
    ("mapping-unknown-entry-key", lambda d, base: base, '[channels]\ngps = { topic = "/fix", tpye = "x" }\n',
     None, r"m\.toml: \[channels\] gps: tpye: unknown key \(known: child, "),
    ("mapping-type-mismatch", lambda d, base: base,
     '[channels]\ngps = { topic = "/fix", type = "sensor_msgs/msg/Imu" }\n', None,
     r"topic /fix: the mapping expects sensor_msgs/msg/Imu, the recording has sensor_msgs/msg/NavSatFix"),
    ("mapping-topic-not-in-bag", lambda d, base: base, '[channels]\ngps = "/fixx"\n', None,
     r"topic /fixx \(mapped to gps\) is not in the recording \(did you mean /fix\?\)"),
    ("mapping-topic-zero-messages", lambda d, base: base, '[channels]\nimu = "/empty"\n', None,
     r"topic /empty \(mapped to imu\) has no messages"),
    ("mapping-role-type-mismatch", lambda d, base: base,
     '[channels]\ngps = { topic = "/fix", role = "odometry" }\n', None,
     r"\[channels\] gps: topic /fix is a sensor_msgs/msg/NavSatFix, which cannot have role 'odometry'"),
    ("mapping-unknown-role", lambda d, base: base, '[channels]\ngps = { topic = "/fix", role = "fix" }\n',
     None, r"\[channels\] gps: unknown role 'fix'"),
    ("mapping-channel-name-collision", lambda d, base: base,
     '[channels]\nodom = "/wheel"\nodom_velocity = "/imu"\n', None,
     r"\[channels\] odom_velocity \(/imu\) makes channel odom_velocity, which odom makes too"),
    ("mapping-negative-param", lambda d, base: base, GOOD_MAP + "[params]\nwater_density = -1.0\n", None,
     r"\[params\]: water_density must be a finite number > 0 \(or null\) \(got -1\.0\)"),
    ("mapping-without-gps-for-gps-odom", lambda d, base: base,
     '[channels]\nwheel = "/wheel"\n[reference]\nposition = "/fix"\n', "gps-odom", r"task gps-odom needs a gps input"),
    ("mapping-two-gps-inputs", lambda d, base: make_bag(d / "b", extra_fix=True),
     GOOD_MAP + "[channels.gps2]\ntopic = \"/fix2\"\n", "gps-odom",
     r"task gps-odom: 2 inputs have role gps \(gps = /fix .*, gps2 = /fix2 .*\): keep one"),
    ("bag-stamps-backwards", lambda d, base: make_bag(d / "b", fix_stamps=[T0 + k * 10**9 for k in (0, 1, 3, 2, 4)]),
     GOOD_MAP, "gps-odom", r"topic /fix: non-increasing header stamps at message 3"),
    ("bag-duplicate-stamps", lambda d, base: make_bag(d / "b", fix_stamps=[T0 + k * 10**9 for k in (0, 1, 1, 2)]),
     GOOD_MAP, "gps-odom", r"topic /fix: non-increasing header stamps at message 2"),
]
register(*(c[0] for c in BAG_REFUSED), "bag-nan-positions")


def _cut(src: Path, dst: Path, frac: float) -> Path:
    data = src.read_bytes()
    return _write(dst, data[: int(len(data) * frac)])


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


@pytest.fixture(scope="module")
def base_bag(tmp_path_factory) -> Path:
    """The bag of :func:`make_bag`, written once for the cases that only change the mapping (read only)."""
    return make_bag(tmp_path_factory.mktemp("bag") / "b")


@pytest.mark.parametrize("case,make,mapping,task,match", BAG_REFUSED, ids=[c[0] for c in BAG_REFUSED])
def test_bag_refused(tmp_path, base_bag, case, make, mapping, task, match):
    rec = make(tmp_path, base_bag)
    args = ["eval", rec, "-f", "ekf", "--out", tmp_path / "o"]
    if mapping is not None:
        (tmp_path / "m.toml").write_text(mapping)
        args += ["--mapping", tmp_path / "m.toml"]
    assert_refused(args + (["--task", task] if task else []), match)


def test_bag_nan_positions_masked_and_counted(tmp_path):
    bag = make_bag(tmp_path / "b", nan_fix=(5, 6, 7))
    (tmp_path / "m.toml").write_text(GOOD_MAP)
    assert_ok(["eval", bag, "--mapping", tmp_path / "m.toml", "--task", "gps-odom", "-f", "ekf",
               "--out", tmp_path / "o"])
    assert report_count(tmp_path / "o", "masked", "gps", "no usable value") == 3


# ---------------------------------------------------------------- task parameters

PARAM_REFUSED = [
    ("param-r-negative", "position", "r=-2", r"task 'position': r must be a finite number > 0 \(got -2\)"),
    ("param-r-infinity", "position", "r=Infinity", r"task 'position': r must be a finite number > 0 \(got inf\)"),
    ("param-r-nan", "position", "r=NaN", r"task 'position': r must be a finite number > 0 \(got nan\)"),
    ("param-r-gps-zero", "gps-odom", "r_gps=0", r"task 'gps-odom': r_gps must be a finite number > 0 \(got 0\)"),
    ("param-R-not-pd", "depth", "R=[[1,2,0],[2,1,0],[0,0,1]]",
     r"task 'depth': R must be a 3x3 symmetric positive-definite matrix .*\(got \[\[1, 2, 0\]"),
    ("param-Q-nan-cell", "sonar", "Q=[1,1,1,1,NaN,1]", r"task 'sonar': Q must be a 6x6 symmetric positive-definite"),
    ("param-R-wrong-size", "dead-reckoning", "R=[1,1]", r"task 'dead-reckoning': R must be an 8x8 .*\(got \[1, 1\]\)"),
    ("param-unknown", "position", "rr=2", r"task 'position': unknown parameter 'rr' \(known: q, r, p0"),
]
register(*(c[0] for c in PARAM_REFUSED))


@pytest.mark.parametrize("case,task,param,match", PARAM_REFUSED, ids=[c[0] for c in PARAM_REFUSED])
def test_task_param_refused(tmp_path, case, task, param, match):
    assert_refused(["eval", "sim/auv-sonar", "--task", task, "--task-param", param, "-f", "ekf",
                    "--out", tmp_path / "o"], match)
