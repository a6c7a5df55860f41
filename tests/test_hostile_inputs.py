"""Issue 33, items 4, 8 and 10 (parts): mapping field lists, special files, TOML nesting, CR-only
Bohai files, huge values in error lines, NaN odometry and a reference that ends early."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hostile import assert_ok, assert_refused, register
from test_hostile_score import deadline  # a FIFO opened after all fails instead of hanging
from replay.adapters.bags.writer import BagOut
from replay.adapters.mapping import from_dict, load_mapping
from replay.roles import SensorInput
from replay.tasks.fusion_inputs import configured, differential
from replay.util.errors import DataError, ReplayError, bounded, shown
from replay.util.regular import MAX_TEXT
from replay.util.tomlfile import MAX_DEPTH, depth

register("mapping-fuse-duplicate", "mapping-fuse-empty", "mapping-differential-gyro",
         "mapping-differential-velocity", "mapping-fuse-and-differential", "space-dev-zero", "tuned-fifo",
         "toml-nesting-bomb", "bohai-cr-only", "mapping-huge-value", "odometry-nan-twist",
         "reference-ends-early")

T0 = 1_700_000_000 * 10**9
BOMBS = {  # nesting bombs that tomllib itself ends in RecursionError, and one it parses (dotted keys)
    "arrays": "a = " + "[" * 100_000 + "]" * 100_000 + "\n",
    "inline-tables": "a = " + "{b=" * 5000 + "1" + "}" * 5000 + "\n",
    "dotted-keys": "a." * 3000 + "b = 1\n",
}


# ------------------------------------------------------------ item 4: fusion field lists

ODOM = {"reference": {"position": "/gt"}}


@pytest.mark.parametrize("spec, message", [
    ({"fuse": ["velocity", "velocity", "rate"]}, "fuse names 'velocity' twice"),
    ({"fuse": []}, "fuse = \\[\\] names no field: leave it out"),
    ({"differential": []}, "differential = \\[\\] names no field"),
    ({"differential": ["gyro"]}, "differential 'gyro': only pose fields are differential"),
    ({"differential": ["velocity"]}, "differential 'velocity': only pose fields are differential"),
    ({"fuse": ["position", "rate"], "differential": ["position"]},
     "'position' is in both fuse and differential"),
])
def test_mapping_field_lists_refused(spec, message):
    with pytest.raises(ReplayError, match=r"m\.toml: \[channels\] odom: " + message):
        from_dict({"channels": {"odom": {"topic": "/odom", **spec}}, **ODOM}, "m.toml")


def test_mapping_field_lists_that_mean_one_thing_pass():
    m = from_dict({"channels": {"odom": {"topic": "/odom", "fuse": ["velocity", "rate"],
                                         "differential": ["position", "attitude"]}}, **ODOM}, "m.toml")
    assert m.entries[0].fusion == {"fuse": ["velocity", "rate"], "differential": ["position", "attitude"]}


def test_roles_of_another_adapter_are_checked_as_a_mapping_is():
    """A frame's roles from elsewhere (the Python API) meet the same rules in the task."""
    with pytest.raises(ReplayError, match="x: fuse names 'rate' twice"):
        configured(SensorInput("odometry", "o", "", fuse=("rate", "rate")), "x")
    with pytest.raises(ReplayError, match="x: 'position' is in both"):
        configured(SensorInput("pose", "p", "", fuse=("position",), differential=("position",)), "x")
    with pytest.raises(ReplayError, match="x: unknown field 'heading'"):
        configured(SensorInput("pose", "p", "", fuse=("heading",)), "x")
    with pytest.raises(ReplayError, match="b: unknown role 'barometer'"):
        SensorInput("barometer", "b", "").spec
    # the default fuse minus a declared differential field: pose deltas replace the absolute pose
    assert configured(SensorInput("pose", "p", "", differential=("position",)), "x")[:2] == (("attitude",), ("position",))


def test_differential_position_without_attitude_refused():
    """The deltas are rotated into the body frame by the attitude: without one they would be
    world-frame velocities read as body velocities."""
    t = np.arange(4.0)
    p = np.column_stack([t, t, 0 * t])
    with pytest.raises(ReplayError, match="x: a differential position needs the input's attitude"):
        differential(t, p, np.ones(4, bool), None, "position", "x")


# ------------------------------------------------------------ item 8: special files, one reader

def test_space_dev_zero_refused_unread(tmp_path):
    """In a subprocess with a timeout: reading /dev/zero would grow until killed."""
    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    code = "import sys; from replay.cli import main; sys.argv = ['replay'] + sys.argv[1:]; main()"
    args = ["tune", "sim/linear", "--filters", "kf", "--split", "seeds", "--trials", "2", "--space", "/dev/zero",
            "--out", str(tmp_path / "t")]
    res = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert "--space /dev/zero: a character device, not a regular file: refusing to read it as a search space" \
        in res.stderr


def test_fifos_refused_unopened(tmp_path):
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    with deadline():
        assert_refused(["eval", "sim/linear", "--tuned", fifo, "--out", tmp_path / "o"],
                       r"--tuned .*fifo\.toml: a FIFO \(named pipe\), not a regular file: refusing to read it "
                       "as a campaign file")
        assert_refused(["tune", "sim/linear", "--filters", "kf", "--split", "seeds", "--space", fifo, "--out",
                        tmp_path / "t"], r"--space .*fifo\.toml: a FIFO")
        assert_refused(["campaign", "run", fifo, "-o", tmp_path / "c"], r"fifo\.toml: a FIFO")
        assert_refused(["rerun", fifo], r"fifo\.toml: a FIFO .*as a replay manifest")
        with pytest.raises(DataError, match="a FIFO .*as a dataset manifest"):
            from replay.data.registry import _read_manifest

            _read_manifest(fifo)
    assert not (tmp_path / "o").exists() and not (tmp_path / "c").exists()


def test_a_text_file_over_the_cap_refused_unread(tmp_path):
    big = tmp_path / "m.toml"
    with open(big, "wb") as fh:
        fh.truncate(MAX_TEXT + 1)  # sparse: nothing written, nothing read
    with pytest.raises(DataError, match=rf"m\.toml: larger than {MAX_TEXT} bytes: refusing to read it as a mapping"):
        load_mapping(big)
    for missing in (tmp_path / "none.toml", tmp_path):
        with pytest.raises(DataError, match="no such file|a directory, not a regular file"):
            load_mapping(missing)


# ------------------------------------------------------------ item 10: TOML nesting, huge values, CR-only

@pytest.mark.parametrize("kind", sorted(BOMBS))
def test_toml_nesting_bomb_is_one_line_everywhere(tmp_path, kind):
    bomb = tmp_path / "bomb.toml"
    bomb.write_text(BOMBS[kind])
    deep = f"tables or arrays nested more than {MAX_DEPTH} deep"
    with pytest.raises(DataError, match=f"bomb.toml: {deep}: not a mapping"):
        load_mapping(bomb)
    assert_refused(["tune", "sim/linear", "--filters", "kf", "--split", "seeds", "--space", bomb, "--out",
                    tmp_path / "t"], rf"--space .*bomb\.toml: {deep}: not a search space")
    assert_refused(["eval", "sim/linear", "--tuned", bomb, "--out", tmp_path / "o"],
                   rf"--tuned .*bomb\.toml: {deep}: not a campaign file")
    assert_refused(["campaign", "run", bomb, "-o", tmp_path / "c"], rf"bomb\.toml: {deep}")


def test_json_nesting_bomb_in_a_manifest_is_one_line(tmp_path):
    for text in ("[" * 100_000 + "]" * 100_000, '{"config": ' + "[" * 40 + "]" * 40 + "}"):
        (tmp_path / "manifest.json").write_text(text)
        assert_refused(["rerun", tmp_path / "manifest.json"],
                       rf"manifest\.json: not a replay manifest \(objects or arrays nested more than {MAX_DEPTH} deep")


def test_depth_counts_without_recursion():
    doc = x = {}
    for _ in range(100_000):
        x["a"] = x = {}
    assert depth(doc) == 100_001 and depth({"a": [1, {"b": 2}]}) == 3 and depth(5) == 0


def test_a_huge_value_is_quoted_by_its_start():
    value = "x" * 100_000_000
    with pytest.raises(ReplayError) as info:
        from_dict({"time": value, **ODOM}, "m.toml")
    line = str(info.value)
    assert len(line) < 200 and line.endswith("(got 'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx'... "
                                             "(100000000 characters))")
    assert shown("ab") == "'ab'" and shown(list(range(1000))).endswith("... (4890 characters)")
    assert len(bounded("y" * 10**6)) < 2100


def test_a_huge_value_in_a_mapping_file_and_a_campaign_file(tmp_path):
    """Values of 10^5 characters (a thousand times the longest line; 10^6 cost 10x the time for the
    same assertions) are named in short lines."""
    mp = tmp_path / "m.toml"
    mp.write_text(f'time = "{"x" * 10**5}"\n[reference]\nposition = "/gt"\n')
    bag = make_bag(tmp_path / "b", ref_seconds=99.0)
    line = assert_refused(["eval", bag, "--mapping", mp, "--out", tmp_path / "o"], r"m\.toml: time must be")
    assert len(line) < 300
    camp = tmp_path / "c.toml"
    camp.write_text(f'[campaign]\nruns = 1\n[[dataset]]\nid = "sim/linear"\ntasks = ["{"t" * 10**5}"]\n'
                    '[[filter]]\nname = "kf"\n')
    line = assert_refused(["campaign", "run", camp, "-o", tmp_path / "c"], r"c\.toml:5: tasks: unknown task 'tt")
    assert len(line) < 400 and "(100000 characters)" in line
    camp.write_text(f'[campaign]\nruns = 1\n{"k" * 10**4} = 1\n')
    line = assert_refused(["campaign", "run", camp, "-o", tmp_path / "c"], r"c\.toml:3: \[campaign\]: 'kkk.*unknown key")
    assert len(line) < 400 and "(10000 characters)" in line


def test_bohai_cr_only_file_loads_exactly_as_its_lf_version(tmp_path):
    sys.path.insert(0, str(Path(__file__).parent))
    from test_bohai import COLS36, synthetic_table, write_lines

    from replay.adapters.bohai import load

    lf = write_lines(tmp_path / "lf.csv", synthetic_table(60), lambda lines: lines.insert(5, "," * (len(COLS36) - 1)))
    a = load(lf)
    for name, end in (("cr.csv", b"\r"), ("crlf.csv", b"\r\n")):
        other = tmp_path / name
        other.write_bytes(lf.read_bytes().replace(b"\n", end))
        b = load(other)
        assert b.report.lines() == a.report.lines()  # the blank line 6 dropped, named as line 6
        assert list(b.channels) == list(a.channels) and list(b.reference) == list(a.reference)
        for group in ("channels", "reference"):
            for k, ch in getattr(a, group).items():
                np.testing.assert_array_equal(getattr(b, group)[k].values, ch.values, err_msg=k)
                np.testing.assert_array_equal(getattr(b, group)[k].valid, ch.valid, err_msg=k)
        assert len(b) == 60


# ------------------------------------------------------------ item 4: NaN odometry, a reference ending early

NAN_AT = (5, 17, 33, 250)  # a NaN linear twist
ALL_NAN = 300  # a NaN position and linear twist


def make_bag(path: Path, ref_seconds: float) -> Path:
    """40 s: /odom Odometry at 10 Hz (1 m/s east; a NaN linear twist at NAN_AT and ALL_NAN, a NaN
    position at ALL_NAN), /gt PoseStamped at 10 Hz for the first ``ref_seconds``."""
    out = BagOut(path)
    T = out.T
    odom = out.connection("/odom", "nav_msgs/msg/Odometry")
    gt = out.connection("/gt", "geometry_msgs/msg/PoseStamped")
    q0, z3 = (0.0, 0.0, 0.0, 1.0), np.zeros(3)
    for k in range(400):
        s = T0 + k * 10**8
        v = (np.nan, 0.0, 0.0) if k in NAN_AT or k == ALL_NAN else (1.0, 0.0, 0.0)
        p = (np.nan, 0.0, 0.0) if k == ALL_NAN else (k / 10, 0, 0)
        out.write(odom, s, out.odometry(s, "odom", "base", p, q0, v, z3))
        if k / 10 < ref_seconds:
            out.write(gt, s, T["geometry_msgs/msg/PoseStamped"](header=out.header(s, "map"),
                                                                pose=out.pose((k / 10, 0, 0), q0)))
    out.close()
    return path


def fusion_eval(tmp_path, ref_seconds: float):
    """``replay eval`` of :func:`make_bag`'s recording, task fusion, one EKF run, into ``tmp_path/o``."""
    bag = make_bag(tmp_path / "b", ref_seconds)
    mp = tmp_path / "m.toml"
    mp.write_text('[channels]\nodom = "/odom"\n[reference]\nposition = "/gt"\n')
    return assert_ok(["eval", bag, "--mapping", mp, "--task", "fusion", "-f", "ekf", "--runs", "1",
                      "-o", tmp_path / "o"])


def test_nan_odometry_counted_and_an_early_reference_scored_honestly(tmp_path):
    res = fusion_eval(tmp_path, ref_seconds=10.0)
    report = json.loads((tmp_path / "o" / "manifest.json").read_text())["adapter_report"]
    lost = [e for e in report if e["action"] == "masked" and e["what"] == "odom_velocity"]
    assert [e["count"] for e in lost] == [len(NAN_AT) + 1] and "NaN or inf" in lost[0]["reason"]
    assert [e["count"] for e in report if e["action"] == "masked" and e["what"] == "odom"] == [1]
    assert f"odom velocity: {len(NAN_AT) + 1} messages not used (/odom: velocity NaN or inf" in res.stderr
    # the reference: 100 samples over 9.9 s of a 39.9 s run; the 300 it would have given after its
    # end (at its 0.1 s step) count as masked: 100 / 400 = 25 % scored, under min_scored_share 0.5
    assert "the reference covers 9.9 s of the run's 39.9 s (25 %: 0.0 s to 9.9 s)" in res.stderr
    row = next(csv.DictReader(open(tmp_path / "o" / "leaderboard.csv")))
    assert int(row["scored"]) == 100 and int(row["masked"]) == 300
    assert " 25.0%!" in res.stdout and "ekf: scored on 100 of 400 reference samples" in res.stdout


def test_a_reference_covering_the_run_adds_nothing(tmp_path):
    res = fusion_eval(tmp_path, ref_seconds=99.0)
    row = next(csv.DictReader(open(tmp_path / "o" / "leaderboard.csv")))
    assert int(row["scored"]) == 400 and int(row["masked"]) == 0 and "covers" not in res.stderr


def test_a_huge_csv_cell_is_quoted_by_its_start(tmp_path):
    sys.path.insert(0, str(Path(__file__).parent))
    from test_bohai import COLS36, synthetic_table, write_lines

    from replay.adapters.bohai import load

    def edit(lines):
        cells = lines[3].split(",")
        cells[COLS36.index("roll")] = "z" * 10**6
        lines[3] = ",".join(cells)

    path = write_lines(tmp_path / "huge.csv", synthetic_table(), edit)
    with pytest.raises(DataError) as info:
        load(path)
    assert "non-numeric value 'zzz" in str(info.value) and "... (1000000 characters) in column roll" in str(info.value)
    assert len(str(info.value)) < 300
