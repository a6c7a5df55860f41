"""The Bohai AUV CSV adapter: real files in ../shared, and bad input built in tmp_path."""
import csv
import hashlib

import numpy as np
import pandas as pd
import pyproj
import pytest

from replay.adapters import get_adapter
from replay.adapters.bohai import COLS31, COLS36, load, mask_jumps
from replay.util.errors import DataError

ROWS = {"20220822_0_0.csv": 3478, "20220822_0_3.csv": 8500, "20220822_0_4.csv": 7614,
        "20220822_0_5.csv": 7067, "20220822_0_6.csv": 7509, "20220625_0_0.csv": 8476}
EPSG = {name: 32649 if name.startswith("20220625") else 32651 for name in ROWS}
BOHAI_SEA = [name for name in ROWS if name.startswith("20220822")]

_frames = {}


def frame_of(bohai_dir, name):
    """Each real file is loaded once per test session."""
    if name not in _frames:
        _frames[name] = load(bohai_dir / name)
    return _frames[name]


# ---------------------------------------------------------------- real files

@pytest.mark.parametrize("name", sorted(ROWS))
def test_rows_crs_and_meta(bohai_dir, name):
    frame = frame_of(bohai_dir, name)
    rows = frame.meta["rows"]
    assert rows["read"] == ROWS[name]
    assert rows["kept"] + rows["dropped"] == rows["read"]
    assert len(frame) == rows["kept"] == ROWS[name]  # nothing to drop in these files
    assert frame.report.count("dropped") == sum(e.count for e in frame.report.find("dropped")
                                                if e.what != "rows") + rows["dropped"]
    assert frame.meta["epsg"] == EPSG[name]
    assert frame.meta["crs"] == f"EPSG:{EPSG[name]}"
    assert frame.meta["layout"] == 36
    assert frame.meta["adapter"] == "bohai-csv"
    assert frame.meta["source"] == str(bohai_dir / name)
    assert frame.meta["sha256"] == hashlib.sha256((bohai_dir / name).read_bytes()).hexdigest()
    sums = dict(reversed(line.split()) for line in (bohai_dir / "SHA256SUMS").read_text().splitlines())
    assert frame.meta["sha256"] == sums[name]
    assert frame.epoch is None
    assert frame.t[0] == 0.0 and np.all(np.diff(frame.t) > 0)
    ref = frame.reference["position"]
    assert ref.values.shape == (len(frame), 2) and ref.components == ("east", "north")
    assert ref.unit == "m" and ref.frame == "ENU local"
    first = int(np.argmax(ref.valid))
    assert np.allclose(ref.values[first], 0.0)  # origin = first valid navigation sample
    assert 0.09 < frame.meta["time"]["median_step"] < 0.103


def test_registered_adapter():
    assert get_adapter("bohai-csv") is load


def test_utm_against_independent_proj(bohai_dir):
    name, index = "20220822_0_6.csv", 1000  # file line 1002
    with open(bohai_dir / name, newline="") as fh:
        rows = list(csv.DictReader(fh))
    lat, lon = float(rows[index]["lat"]), float(rows[index]["lon"])
    east, north = pyproj.Proj(proj="utm", zone=51, ellps="WGS84")(lon, lat)
    frame = frame_of(bohai_dir, name)
    got = frame.reference["position"].values[index] + np.array(frame.meta["origin"])
    assert abs(got[0] - east) < 1e-6 and abs(got[1] - north) < 1e-6
    gps = frame.channels["gps_position"].values[index] + np.array(frame.meta["origin"])
    east, north = pyproj.Proj(proj="utm", zone=51, ellps="WGS84")(
        float(rows[index]["lon_gps"]), float(rows[index]["lat_gps"]))
    assert abs(gps[0] - east) < 1e-6 and abs(gps[1] - north) < 1e-6


QUIRKS = [  # column, finding in 20220822_0_6 (README: "Measured in these files")
    ("vn", "|value| up to 1736.1 > 10 m/s limit"),
    ("ve", "|value| up to 1800.6 > 10 m/s limit"),
    ("vl", "|value| up to 1893.1 > 10 m/s limit"),
    ("ax", "> 50 m/s^2 limit"),
    ("ay", "|value| up to 18736.2 > 50 m/s^2 limit"),
    ("pos_accuracy", "duplicate of column vf"),
    ("af", "duplicate of column ax"),
    ("al", "duplicate of column ay"),
    ("au", "duplicate of column az"),
    ("wf", "duplicate of column wx"),
    ("wl", "duplicate of column wy"),
    ("wu", "duplicate of column wz"),
    ("height", "duplicate of column wx"),
    ("numsats", "duplicate of column time"),
    ("posmode", "duplicate of column time"),
    ("velmode", "duplicate of column time"),
    ("orimode", "duplicate of column time"),
    ("depth", "all zero"),
]


@pytest.mark.parametrize("column, finding", QUIRKS)
def test_quirk_detected_and_reported(bohai_dir, column, finding):
    frame = frame_of(bohai_dir, "20220822_0_6.csv")
    assert finding in frame.meta["dropped_columns"][column]
    entries = frame.report.find("dropped", column)
    assert len(entries) == 1 and entries[0].count == len(frame)
    assert finding in entries[0].reason
    assert column not in frame.channels
    assert all(column not in ch.components for ch in frame.channels.values())


def test_vf_is_dropped_too(bohai_dir):
    frame = frame_of(bohai_dir, "20220822_0_6.csv")
    assert "|value| up to 188.5 > 10 m/s limit" in frame.meta["dropped_columns"]["vf"]


@pytest.mark.parametrize("name", BOHAI_SEA)
def test_no_quirky_column_passes_in_any_file(bohai_dir, name):
    frame = frame_of(bohai_dir, name)
    for column, _ in QUIRKS + [("vf", "")]:
        assert column in frame.meta["dropped_columns"], column
    passed = {c for ch in frame.channels.values() for c in ch.components}
    assert {"roll", "pitch", "yaw", "wx", "wy", "wz"} <= passed
    assert frame.meta["dropped_columns"]["time_gps"] == "all zero"


def test_velocity_disagreeing_with_track_is_dropped(bohai_dir):
    # 20220822_0_0: vn/ve stay within 0.04 m/s while the track moves at ~3 m/s
    frame = frame_of(bohai_dir, "20220822_0_0.csv")
    for column in ("vn", "ve"):
        assert "disagrees with position-derived" in frame.meta["dropped_columns"][column]
    assert frame.meta["dropped_columns"]["alt_gps"] == "all zero"
    assert "gps_alt" not in frame.channels


@pytest.mark.parametrize("name, line, step", [
    ("20220822_0_5.csv", 307, 697.0),
    ("20220822_0_0.csv", 236, 234.1),
    ("20220822_0_6.csv", 3096, 187.2)])
def test_jump_caught(bohai_dir, name, line, step):
    frame = frame_of(bohai_dir, name)
    jumps = frame.meta["jumps"]
    assert abs(jumps["largest_m"] - step) < 0.1
    found = [s for s in jumps["steps"] if s["line"] == line]
    assert len(found) == 1 and abs(found[0]["step_m"] - step) < 0.1
    valid = frame.reference["position"].valid
    i = line - 2
    assert not (valid[i - 1] and valid[i])  # one side of the jump is masked
    entry = [e for e in frame.report.find("masked", "position") if "jumps" in e.reason][0]
    assert f"largest {step:.1f} m at line {line}" in entry.reason
    assert jumps["masked"] == jumps["masked_gps"] + jumps["masked_kinematic"]
    assert jumps["masked"] == frame.report.count("masked") - sum(
        e.count for e in frame.report.entries if e.action == "masked" and e.what != "position")


def test_displaced_start_of_0_5_masked_rest_kept(bohai_dir):
    frame = frame_of(bohai_dir, "20220822_0_5.csv")
    valid = frame.reference["position"].valid
    assert not valid[:305].any()  # lines 2..306: 695 m off the GPS fixes, before the 697 m jump
    assert valid[305:420].all()
    assert valid.sum() > 0.95 * len(frame)
    assert frame.meta["jumps"]["events"] == 2


@pytest.mark.parametrize("name", sorted(ROWS))
def test_masked_reference_has_no_jump(bohai_dir, name):
    frame = frame_of(bohai_dir, name)
    ref = frame.reference["position"]
    keep = np.flatnonzero(ref.valid)
    step = np.hypot(*np.diff(ref.values[keep], axis=0).T)
    per_tenth = step / np.diff(frame.t[keep]) * 0.1
    assert per_tenth.max() <= 5.0
    assert frame.meta["jumps"]["events"] >= 2
    assert ref.valid.sum() > 0.7 * len(frame)


def test_stale_gps_in_0_4(bohai_dir):
    frame = frame_of(bohai_dir, "20220822_0_4.csv")
    gps = frame.meta["gps"]
    assert gps["longest_stale_s"] >= 600
    assert gps["fresh"] == 36 and gps["stale"] == len(frame) - 36
    ch = frame.channels["gps_position"]
    valid = np.flatnonzero(ch.valid)
    assert len(valid) == gps["valid"] == gps["fresh"] - gps["outliers"]
    assert np.all(np.any(ch.values[valid] != ch.values[valid - 1], axis=1))  # each a new fix
    entry = frame.report.find("info", "gps_position")[0]
    assert "longest stale stretch 661.0 s" in entry.reason
    assert frame.channels["gps_alt"].valid.sum() < 810
    assert frame.report.find("masked", "gps_alt")  # a zero altitude


def test_attitude_yaw_and_speed_in_0_6(bohai_dir):
    frame = frame_of(bohai_dir, "20220822_0_6.csv")
    att = frame.channels["attitude"]
    assert att.components == ("roll", "pitch", "yaw") and att.angles == (0, 1, 2)
    assert att.unit == "rad" and "0 = east" in att.convention and "left side up" in att.convention
    assert frame.meta["yaw_course"]["median_abs_rad"] < 0.2
    assert 2.2 < frame.meta["speed"]["median"] < 2.6
    assert frame.report.find("info", "attitude")
    gyro = frame.channels["gyro"]
    assert gyro.unit == "rad/s" and gyro.components == ("wx", "wy", "wz")
    assert frame.meta["gyro_attitude"]["wz_yaw"] > 0.9


def test_gps_time_of_day_in_lake_file(bohai_dir):
    frame = frame_of(bohai_dir, "20220625_0_0.csv")
    tod = frame.meta["gps_time_of_day"]
    assert tod["t0_hhmmss"] == "05:20:13.6"
    assert frame.epoch is None


def test_31_column_layout(bohai_dir, tmp_path):
    table = pd.read_csv(bohai_dir / "20220822_0_6.csv", nrows=2000)
    table = table.rename(columns={"alt_gps": "alt"})[list(COLS31)]
    path = tmp_path / "six_31.csv"
    table.to_csv(path, index=False, float_format="%.12g")
    frame = load(path)
    assert frame.meta["layout"] == 31 and len(frame) == 2000
    assert frame.meta["epsg"] == 32651
    assert "gps_position" not in frame.channels and "gps" not in frame.meta
    assert {"attitude", "gyro", "alt"} <= set(frame.channels)
    assert frame.channels["alt"].valid.sum() < 300  # only new values
    assert frame.meta["dropped_columns"]["wf"].startswith("duplicate of column wx")
    assert frame.meta["jumps"]["events"] == 2  # 129.7 m at 136.7 s, 61.2 m at 206.8 s
    ref = frame.reference["position"]
    keep = np.flatnonzero(ref.valid)
    assert (np.hypot(*np.diff(ref.values[keep], axis=0).T) / np.diff(frame.t[keep]) * 0.1).max() <= 5.0


# ---------------------------------------------------------------- jump masking

def test_mask_jumps_spike_segment_and_step():
    t = np.arange(300) * 0.1
    p = np.column_stack([t * 2.0, np.zeros_like(t)])  # 2 m/s east
    p[50] += [0, 40]  # single-sample spike
    p[100:120] += [300, 0]  # displaced stretch that comes back
    keep = mask_jumps(t, p)
    assert np.flatnonzero(~keep).tolist() == [50] + list(range(100, 120))
    q = np.column_stack([t * 2.0, np.zeros_like(t)])
    q[200:] += [0, 100]  # persistent step of 100 m: masked next to it, not to the end
    keep = mask_jumps(t, q)
    masked = np.flatnonzero(~keep)
    assert 0 < len(masked) < 150 and keep[-50:].all()
    kept = np.flatnonzero(keep)
    assert (np.hypot(*np.diff(q[kept], axis=0).T) / np.diff(t[kept]) * 0.1).max() <= 5.0


# ---------------------------------------------------------------- bad input

def synthetic_table(n=40):
    """A plausible 36-column log: 1 m/s east near 40.6 N 121.0 E, 10 Hz, a GPS fix every 10 rows."""
    rng = np.random.default_rng(1)
    t = np.round(np.arange(n) * 0.1, 3)
    lon, lat = pyproj.Transformer.from_crs(32651, 4326, always_xy=True).transform(
        330000.0 + t, np.full(n, 4496000.0))
    fix = np.arange(n) // 10 * 10
    cols = {c: np.round(rng.normal(0, 0.1, n), 4) for c in COLS36}
    cols.update(lat=lat, lon=lon, lat_gps=lat[fix], lon_gps=lon[fix], alt_gps=12.0 + fix * 0.01,
                yaw=np.round(rng.normal(0, 0.02, n), 4), time=t, time_gps=np.zeros(n),
                numsats=np.full(n, 9.0), navstat=np.full(n, 1.0), posmode=np.full(n, 4.0),
                velmode=np.full(n, 4.0), orimode=np.full(n, 4.0),
                pos_accuracy=np.abs(cols["pos_accuracy"]), vel_accuracy=np.abs(cols["vel_accuracy"]),
                depth=np.zeros(n), height=np.abs(cols["height"]) + 5,
                vn=np.round(rng.normal(0, 0.02, n), 4), ve=np.round(rng.normal(1, 0.02, n), 4))
    return pd.DataFrame(cols)[list(COLS36)]


def write_lines(path, table, edit=None):
    """Write ``table`` as CSV; ``edit(lines)`` may change the text lines (header = lines[0])."""
    lines = table.to_csv(index=False).splitlines()
    if edit:
        edit(lines)
    path.write_text("\n".join(lines) + "\n")
    return path


def one_line_error(path):
    with pytest.raises(DataError) as info:
        load(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    return message


def test_synthetic_file_loads(tmp_path):
    frame = load(write_lines(tmp_path / "ok.csv", synthetic_table()))
    assert len(frame) == 40 and frame.meta["rows"]["dropped"] == 0
    assert frame.reference["position"].valid.all()
    assert frame.meta["gps"]["fresh"] == 3
    assert np.allclose(frame.reference["position"].values[-1], [3.9, 0.0], atol=1e-6)
    assert "ve" in frame.channels and "numsats" in frame.channels


def test_missing_file(tmp_path):
    message = one_line_error(tmp_path / "nope.csv")
    assert "file not found" in message


def test_empty_file(tmp_path):
    path = tmp_path / "empty.csv"
    path.write_text("")
    assert "file is empty" in one_line_error(path)
    path.write_text("\n  \n")
    assert "file is empty" in one_line_error(path)


def test_header_only(tmp_path):
    path = tmp_path / "header.csv"
    path.write_text(",".join(COLS36) + "\n")
    assert "header only" in one_line_error(path)


def test_missing_columns(tmp_path):
    path = write_lines(tmp_path / "cols.csv", synthetic_table().drop(columns=["time", "lat_gps"]))
    message = one_line_error(path)
    assert "missing columns lat_gps, time" in message and "36-column layout" in message


def test_non_numeric_cell(tmp_path):
    def edit(lines):
        cells = lines[6].split(",")
        cells[COLS36.index("roll")] = "abc"
        lines[6] = ",".join(cells)
    message = one_line_error(write_lines(tmp_path / "text.csv", synthetic_table(), edit))
    assert "row 7" in message and "column roll" in message and "'abc'" in message


def test_all_nan_and_blank_rows_dropped_and_counted(tmp_path):
    def edit(lines):
        lines.insert(5, "," * (len(COLS36) - 1))  # line 6
        lines.insert(12, "")  # line 13
    frame = load(write_lines(tmp_path / "nan.csv", synthetic_table(), edit))
    assert frame.meta["rows"] == {"read": 42, "kept": 40, "dropped": 2}
    entry = frame.report.find("dropped", "rows")[0]
    assert entry.count == 2 and "lines 6, 13" in entry.reason


def test_nan_lat_lon_masks_reference(tmp_path):
    table = synthetic_table()
    table.loc[7, "lat"] = np.nan
    frame = load(write_lines(tmp_path / "latnan.csv", table))
    assert len(frame) == 40
    assert not frame.reference["position"].valid[7] and frame.reference["position"].valid.sum() == 39
    entry = [e for e in frame.report.find("masked", "position") if "lat/lon" in e.reason][0]
    assert entry.count == 1 and "line 9" in entry.reason


def test_zero_gps_fix_invalid_and_reported(tmp_path):
    table = synthetic_table()
    table.loc[5, ["lat_gps", "lon_gps"]] = 0.0  # line 7; line 8 returns to the held fix
    frame = load(write_lines(tmp_path / "gpszero.csv", table))
    gps = frame.channels["gps_position"]
    assert not gps.valid[5] and not gps.valid[6] and gps.valid.sum() == 3
    assert frame.meta["gps"]["implausible"] == 1
    entry = frame.report.find("masked", "gps_position")[0]
    assert entry.count == 1 and "line 7" in entry.reason


def test_exact_duplicate_row_dropped(tmp_path):
    def edit(lines):
        lines.insert(9, lines[8])  # line 10 repeats line 9
    frame = load(write_lines(tmp_path / "dup.csv", synthetic_table(), edit))
    assert len(frame) == 40 and frame.meta["rows"]["dropped"] == 1
    entry = frame.report.find("dropped", "rows")[0]
    assert entry.count == 1 and "exact duplicates" in entry.reason and "line 10" in entry.reason


def test_duplicate_timestamp_with_other_values_fails(tmp_path):
    table = synthetic_table()
    table.loc[11, "time"] = table.loc[10, "time"]  # lines 12 and 13
    message = one_line_error(write_lines(tmp_path / "duptime.csv", table))
    assert "row 13" in message and "duplicate timestamp" in message and "line 12" in message


def test_decreasing_time_fails(tmp_path):
    table = synthetic_table()
    table.loc[20, "time"] = 0.5  # line 22
    message = one_line_error(write_lines(tmp_path / "back.csv", table))
    assert "row 22" in message and "time decreases" in message


def test_ragged_row_fails_with_line(tmp_path):
    def edit(lines):
        lines[4] += ",1,2"  # line 5 has 38 fields
    message = one_line_error(write_lines(tmp_path / "ragged.csv", synthetic_table(), edit))
    assert "row 5" in message
