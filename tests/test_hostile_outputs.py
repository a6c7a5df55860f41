"""Hostile output locations for ``replay eval --out`` (corpus: tests/hostile.py).

Each case is refused with one line before any computation (``evaluate`` is replaced by a
function that fails the test), and leaves every input and any existing directory byte for
byte as it was. Inputs: a lake-trial log (plain file), a Bohai-named file in a
``--data-dir`` (located by the registry), a ROS 2 bag directory and a topic mapping; only
their paths matter here, as the output is refused before they are read.
"""
from __future__ import annotations

import hashlib
import json
import subprocess

import pytest
from hostile import assert_ok, assert_refused, register

LOG = "lake.csv"
SIM = ["sim/ungm", "--task", "ungm", "--filters", "ekf"]


def _setup_plain(d):
    (d / LOG).write_text("# replay lake-trial log\ntime_s,depth_m\n0,1\n1,1.1\n")


def _setup_data_dir(d):
    (d / "data").mkdir()
    (d / "data" / "20220822_0_6.csv").write_text("not read: the output is refused first\n")


def _setup_bag(d):
    (d / "bag").mkdir()
    (d / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (d / "m.toml").write_text("[reference]\nposition = \"/fix\"\n")


def _setup_foreign(d):
    (d / "mine").mkdir()
    (d / "mine" / "thesis.tex").write_text("months of work\n")


def _setup_file(d):
    (d / "notes.txt").write_text("a regular file\n")


def _setup_eval_plus_file(d):
    assert_ok(["eval", *SIM, "--runs", "1", "-o", d / "run"])
    (d / "run" / "notes.txt").write_text("added by the user\n")


def _setup_eval_here(d):
    assert_ok(["eval", *SIM, "--runs", "1", "-o", d])  # d (empty) becomes a replay eval output


def _setup_campaign(d):
    (d / "camp" / "units" / "abc").mkdir(parents=True)
    (d / "camp" / "units" / "abc" / "0.json").write_text("{}")


def _setup_other_kind(d):
    (d / "exp").mkdir()
    (d / "exp" / ".replay-output.json").write_text(json.dumps({"tool": "replay", "kind": "replay campaign",
                                                                "files": ["x"]}))
    (d / "exp" / "x").write_text("1")


CASES = {
    "out-is-dataset-file": (_setup_plain, [LOG, "--task", "depth", "-o", LOG],
                            r"^replay: error: --out lake\.csv: is an input of this command; refusing to overwrite it$"),
    "out-contains-dataset-file": (_setup_plain, [LOG, "--task", "depth", "-o", "."],
                                  r"--out \.: contains the input lake\.csv; refusing to replace it$"),
    "out-is-data-dir-dataset": (_setup_data_dir, ["bohai/20220822_0_6", "--data-dir", "data", "--task", "position",
                                                  "-o", "data/20220822_0_6.csv"],
                                r"--out data/20220822_0_6\.csv: is an input of this command"),
    "out-is-data-dir": (_setup_data_dir, ["bohai/20220822_0_6", "--data-dir", "data", "-o", "data"],
                        r"--out data: contains the input data/20220822_0_6\.csv; refusing to replace it$"),
    "out-inside-ros2-bag-dir": (_setup_bag, ["bag", "--task", "gps-odom", "-o", "bag/out"],
                                r"--out bag/out: lies inside the input bag; refusing to write there$"),
    "out-is-mapping-file": (_setup_bag, ["bag", "--task", "gps-odom", "--mapping", "m.toml", "-o", "m.toml"],
                            r"--out m\.toml: is an input of this command; refusing to overwrite it$"),
    "out-non-replay-directory": (_setup_foreign, [*SIM, "-o", "mine"],
                                 r"--out mine: is a non-empty directory that is not a replay eval output "
                                 r"\(it holds 'thesis\.tex'\); refusing to replace it"),
    "out-is-regular-file": (_setup_file, [*SIM, "-o", "notes.txt"], r"--out notes\.txt: is a file, not a directory$"),
    "out-under-regular-file": (_setup_file, [*SIM, "-o", "notes.txt/run"],
                               r"--out notes\.txt/run: notes\.txt is a file, not a directory$"),
    "out-eval-set-with-added-file": (_setup_eval_plus_file, [*SIM, "-o", "run"],
                                     r"--out run: holds 'notes\.txt', which is not part of the replay eval output; "
                                     r"refusing to replace the directory"),
    "out-campaign-directory": (_setup_campaign, [*SIM, "-o", "camp"],
                               r"--out camp: is a non-empty directory that is not a replay eval output "
                               r"\(it holds 'units'\)"),
    "out-other-replay-kind": (_setup_other_kind, [*SIM, "-o", "exp"],
                              r"--out exp: holds a 'replay campaign' output, not a replay eval output"),
    "out-is-current-directory": (_setup_eval_here, [*SIM, "-o", "."],
                                 r"--out \.: holds the current directory, which replacing it as a whole would "
                                 r"remove; run from elsewhere"),
    "mcap-inside-out": (_setup_file, [*SIM, "-o", "run", "--mcap", "run/run.mcap"],
                        r"--mcap run/run\.mcap: overlaps the output directory run, which is replaced as a whole$"),
    "ros2-bag-around-out": (_setup_file, [*SIM, "-o", "res/run", "--ros2-bag", "res"],
                            r"--ros2-bag res: overlaps the output directory res/run"),
}
register(*CASES)


def _snapshot(d):
    return {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(d.rglob("*")) if p.is_file()}


def _no_compute(monkeypatch):
    def boom(*a, **k):
        raise AssertionError("computed although the output was refused")

    # replay eval's one call (eval_job) binds evaluate at its import: patched there first (imported with the
    # real one bound), then at its source
    monkeypatch.setattr("replay.outputs.eval_job.evaluate", boom)
    monkeypatch.setattr("replay.run.evaluation.evaluate", boom)


@pytest.mark.parametrize("case", sorted(CASES))
def test_refused_before_computing_and_nothing_touched(case, tmp_path, monkeypatch):
    setup, args, match = CASES[case]
    setup(tmp_path)
    before = _snapshot(tmp_path)
    _no_compute(monkeypatch)
    assert_refused(["eval", *args], match, cwd=tmp_path)
    assert _snapshot(tmp_path) == before


register("out-read-only-mount")


def test_read_only_mount_refused(tmp_path, monkeypatch):
    """A read-only tmpfs (root ignores file modes, not a read-only mount); skipped without mount."""
    mnt = tmp_path / "ro"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,ro", "tmpfs", str(mnt)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.decode().strip()}")
    _no_compute(monkeypatch)
    try:
        assert_refused(["eval", *SIM, "-o", "ro/run"], r"--out ro/run: ro is on a read-only file system$",
                       cwd=tmp_path)
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=True)


def test_new_runs_go_to_new_numbered_directories(tmp_path):
    """Without --out, each eval gets the next runs/<dataset>/<task>/NNN; latest points to it."""
    for _ in range(2):
        assert_ok(["eval", *SIM, "--runs", "1"], cwd=tmp_path)
    base = tmp_path / "runs" / "sim_ungm" / "ungm"
    assert sorted(p.name for p in base.iterdir()) == ["001", "002", "latest"]
    assert (base / "latest").resolve() == (base / "002").resolve()
    assert (base / "001" / "manifest.json").is_file() and (base / "002" / "manifest.json").is_file()


def test_eval_output_replaced_and_report_goes_with_it(tmp_path):
    """The positive counterpart: an eval set (with a `replay report` inside) and a set written
    before markers existed are replaced as a whole; an empty directory is used."""
    assert_ok(["eval", *SIM, "--runs", "1", "-o", "run"], cwd=tmp_path)
    (tmp_path / "run" / "report").mkdir()
    (tmp_path / "run" / "report" / "report.html").write_text("<html/>")
    assert_refused(["eval", *SIM, "--runs", "2", "-o", "run"], r"--out run: holds an earlier replay eval "
                   r"output; pass --force", cwd=tmp_path)  # never replaced silently
    assert_ok(["eval", *SIM, "--runs", "2", "-o", "run", "--force"], cwd=tmp_path)
    assert not (tmp_path / "run" / "report").exists()
    assert json.loads((tmp_path / "run" / "manifest.json").read_text())["config"]["runs"] == 2
    (tmp_path / "run" / ".replay-output.json").unlink()  # as written by earlier versions
    (tmp_path / "run" / "runs.csv").unlink()  # (no marker, no runs.csv)
    assert_ok(["eval", *SIM, "--runs", "3", "-o", "run", "--force"], cwd=tmp_path)
    assert (tmp_path / "run" / ".replay-output.json").is_file()
    (tmp_path / "empty").mkdir()
    assert_ok(["eval", *SIM, "--runs", "1", "-o", "empty"], cwd=tmp_path)
    assert (tmp_path / "empty" / "leaderboard.csv").is_file()
