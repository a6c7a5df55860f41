"""``replay rerun``: a manifest is checked before any work, then the run is repeated and
every recorded result compared exactly (replay/run/rerun.py; hostile manifests: tests/test_hostile_campaign.py)."""
from __future__ import annotations

import copy
import json

import pytest
from hostile import assert_ok, assert_refused

from replay.run import pipeline, rerun


@pytest.fixture(scope="module")
def manifest(tmp_path_factory):
    """A valid manifest of a simulated dataset (its checksum is null: the simulator and its
    recorded parameters identify it)."""
    d = tmp_path_factory.mktemp("ev")
    assert_ok(["eval", "sim/auv-sonar", "-f", "ekf,ukf", "--runs", "2", "--dataset-param", "steps=20", "-o", d])
    return json.loads((d / "manifest.json").read_text()), d / "manifest.json"


def _write(tmp_path, man):
    path = tmp_path / "manifest.json"
    path.write_text(json.dumps(man))
    return path


def test_simulated_manifest_with_null_checksum_is_reproduced(manifest, tmp_path):
    man, path = manifest
    assert man["config"]["dataset_sha256"] is None
    res = assert_ok(["rerun", path, "-o", tmp_path / "again"])
    assert res.stdout.rstrip().endswith("reproduced: every recorded result equals the rerun's (timing and versions not compared)")
    again = json.loads((tmp_path / "again" / "manifest.json").read_text())
    assert again["results"]["ukf"]["pos_rmse"] == man["results"]["ukf"]["pos_rmse"]
    assert again["config"]["config_hashes"] == man["config"]["config_hashes"]


def test_changed_recorded_value_is_not_reproduced(manifest, tmp_path):
    man = copy.deepcopy(manifest[0])
    was = man["results"]["ukf"]["pos_rmse"]
    man["results"]["ukf"]["pos_rmse"] = was + 1e-12
    path = _write(tmp_path, man)
    assert_refused(["rerun", "-q", path], rf"{path}: not reproduced: ukf\.pos_rmse: {was + 1e-12!r} -> {was!r}$")


def test_rmse_deleted_with_its_interval_is_found_after_the_rerun(manifest, tmp_path):
    """Deleting a value and its interval passes the schema check; the rerun's keys catch it."""
    man = copy.deepcopy(manifest[0])
    del man["results"]["ekf"]["yaw_rmse"], man["results"]["ekf"]["yaw_rmse_ci95"]
    path = _write(tmp_path, man)
    rerun.check(json.loads(path.read_text()), path)  # nothing visible before the rerun
    assert_refused(["rerun", "-q", path], r"not reproduced: ekf\.yaw_rmse: not recorded \(deleted from the manifest\?\)")


@pytest.mark.parametrize("key", list(rerun.CONFIG))
def test_every_config_key_is_required(manifest, tmp_path, key, monkeypatch):
    monkeypatch.setattr(rerun, "repeat", lambda *a, **k: pytest.fail("computed despite a bad manifest"))
    man = copy.deepcopy(manifest[0])
    del man["config"][key]
    path = _write(tmp_path, man)
    assert_refused(["rerun", path], rf"{path}: config\.{key}: missing \(expected ")


@pytest.mark.parametrize("edit,match", [
    (("runs", 0), r"config\.runs: expected an integer in \[1, 1000000\], got 0$"),
    (("runs", 10 ** 7), r"config\.runs: expected an integer in \[1, 1000000\], got 10000000$"),
    (("seed", -1), r"config\.seed: expected an integer in \[0, 9223372036854775807\], got -1$"),
    (("first", 0), r"config\.first: expected an integer >= 1 \(or null\), got 0$"),
    (("divergence_threshold", -1), r"config\.divergence_threshold: expected a finite number > 0 \(or null\), got -1$"),
    (("divergence_threshold", float("inf")), r"config\.divergence_threshold: expected a finite number > 0"),
    (("alignment", "spin"), r"config\.alignment: expected one of none, yaw, se3, sim3, got 'spin'$"),
    (("filters", []), r"config\.filters: empty"),
    (("filters", ["ekf", "ekf"]), r"config\.filters: a filter is listed twice"),
    (("task_params", None), r"config\.task_params: expected an object of task parameters, got NoneType"),
])
def test_values_out_of_range_refused(manifest, tmp_path, edit, match, monkeypatch):
    monkeypatch.setattr(rerun, "repeat", lambda *a, **k: pytest.fail("computed despite a bad manifest"))
    man = copy.deepcopy(manifest[0])
    man["config"][edit[0]] = edit[1]
    assert_refused(["rerun", _write(tmp_path, man)], match)


def test_out_onto_the_manifest_refused_before_work(manifest, monkeypatch):
    monkeypatch.setattr(rerun, "repeat", lambda *a, **k: pytest.fail("computed despite a refused --out"))
    _, path = manifest
    before = path.read_bytes()
    assert_refused(["rerun", path, "-o", path.parent], r"--out .*: contains the input .*manifest\.json")
    assert path.read_bytes() == before


def test_changed_data_file_is_not_reproduced(tmp_path):
    """A file dataset's checksum is recorded and compared: one changed cell is found."""
    log = tmp_path / "lake.csv"
    assert_ok(["datasets", "make", "sim/lake-depth", "--out", log, "--seed", "0"])
    assert_ok(["eval", log, "--adapter", "lake", "-f", "ekf", "--first", "50", "-o", tmp_path / "ev"])
    path = tmp_path / "ev" / "manifest.json"
    sha = json.loads(path.read_text())["config"]["dataset_sha256"]
    assert len(sha) == 64
    assert_ok(["rerun", path])
    lines = log.read_text().splitlines(keepends=True)
    last = lines[-1].split(",")
    last[-1] = last[-1].rstrip("\n") + "1\n"  # a digit more in the last row (outside --first 50)
    log.write_text("".join(lines[:-1]) + ",".join(last))
    pipeline.forget_frames()  # a new process would read the file again
    assert_refused(["rerun", "-q", path], rf"not reproduced: dataset checksum {sha} -> [0-9a-f]{{64}}$")


def test_rerun_compares_exactly_whatever_the_filter_class_declares(monkeypatch):
    """No tolerance: a class attribute RERUN_RTOL (an earlier version's) loosens nothing."""
    from types import SimpleNamespace

    from replay.run import rerun
    from replay.filters.kalman import EKF

    man = {"config": {"dataset_sha256": None, "config_hashes": {"ekf": "h"}},
           "results": {"ekf": {"pos_rmse": 2.0, "rerun_rtol": 0.25}}}
    ev = SimpleNamespace(config={"dataset_sha256": None},
                         results=[SimpleNamespace(name="ekf", config_hash="h", summary={"pos_rmse": 2.001})])
    monkeypatch.setattr(EKF, "RERUN_RTOL", 0.25, raising=False)
    assert rerun.differences(man, ev) == ["ekf.pos_rmse: 2.0 -> 2.001"]
    ev.results[0].summary["pos_rmse"] = 2.0
    assert rerun.differences(man, ev) == []
