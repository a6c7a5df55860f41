"""``replay rerun`` of a manifest written before the reference provenance (no ``dataset.reference``,
no ``reference`` column): rerun as it was then, the newer columns not compared, the old meaning of
``worse_than_measurements`` checked, said in one note (replay/run/rerun.py)."""
from __future__ import annotations

import copy
import json
from types import SimpleNamespace

import pytest
from hostile import assert_ok, assert_refused

from replay.run import rerun

NOTE = "was written before the reference provenance (no dataset.reference)"


@pytest.fixture(scope="module")
def current(tmp_path_factory):
    """A manifest of today's format, with a raw-measurements row (its worse_than_measurements)."""
    d = tmp_path_factory.mktemp("ev")
    assert_ok(["eval", "sim/lake-depth", "-f", "ekf,measurements", "--runs", "3", "-q", "-o", d])
    return json.loads((d / "manifest.json").read_text())


def _old(man: dict) -> dict:
    """``man`` as written before the reference provenance: without the keys it added."""
    old = copy.deepcopy(man)
    del old["dataset"]["reference"]
    for row in old["results"].values():
        for key in rerun.SINCE_PROVENANCE:
            row.pop(key, None)
    return old


def _write(path, man):
    path.write_text(json.dumps(man))
    return path


def test_a_manifest_of_the_old_format_is_rerun_and_said_so(current, tmp_path, caplog):
    assert current["dataset"]["reference"]["kind"] == "simulated truth"
    assert current["results"]["ekf"]["reference"] == "simulated truth"
    assert current["results"]["ekf"]["worse_than_measurements"] is False  # 0.081 m against 0.121 m
    path = _write(tmp_path / "old.json", _old(current))
    res = assert_ok(["rerun", path])
    assert res.stdout.rstrip().endswith("reproduced: every recorded result equals the rerun's (timing and "
                                        "versions not compared)")
    notes = [r.getMessage() for r in caplog.records if NOTE in r.getMessage()]  # replay: note: on stderr
    assert len(notes) == 1 and "reference, reference_shares" in notes[0], notes
    caplog.clear()
    assert_ok(["rerun", _write(tmp_path / "new.json", current)])
    assert not [r for r in caplog.records if NOTE in r.getMessage()]  # today's format: no note


def test_the_old_format_loosens_no_recorded_number(current, tmp_path):
    old = _old(current)
    was = old["results"]["ekf"]["pos_rmse"]
    old["results"]["ekf"]["pos_rmse"] = was * 1.01
    path = _write(tmp_path / "old.json", old)
    assert_refused(["rerun", "-q", path], rf"not reproduced: ekf\.pos_rmse: {was * 1.01!r} -> {was!r}$")


def test_todays_format_still_compares_the_reference_column(current, tmp_path):
    new = copy.deepcopy(current)
    del new["results"]["ekf"]["reference"]  # dataset.reference kept: today's format, a deleted column
    path = _write(tmp_path / "new.json", new)
    assert_refused(["rerun", "-q", path], r"not reproduced: ekf\.reference: not recorded \(deleted from the manifest\?\)")


def _ev(rows: dict):
    return SimpleNamespace(config={"dataset_sha256": None}, results=[
        SimpleNamespace(name=f, config_hash="h" + f, summary=row) for f, row in rows.items()])


def test_worse_than_measurements_is_compared_under_its_rule_of_then():
    """Before: the mean RMSE above the measurements' (True here); since: only a paired difference above
    zero with its interval (the rerun's row: not judged, "")."""
    rows = {"ekf": {"pos_rmse": 1.1, "worse_than_measurements": "", "reference": "simulated truth"},
            "measurements": {"pos_rmse": 1.0, "reference": "simulated truth"}}
    cfg = {"dataset_sha256": None, "config_hashes": {f: "h" + f for f in rows}}
    recorded = {"ekf": {"pos_rmse": 1.1, "worse_than_measurements": True}, "measurements": {"pos_rmse": 1.0}}
    old = {"config": cfg, "results": recorded, "dataset": {}}
    assert rerun.before_provenance(old)
    assert rerun.differences(old, _ev(rows)) == []
    old["results"]["ekf"]["worse_than_measurements"] = False
    assert rerun.differences(old, _ev(rows)) == ["ekf.worse_than_measurements: False -> True"]
    new = {"config": cfg, "dataset": {"reference": {"kind": "simulated truth"}},
           "results": {f: dict(r) for f, r in rows.items()}}
    assert not rerun.before_provenance(new) and rerun.differences(new, _ev(rows)) == []
    new["results"]["ekf"]["worse_than_measurements"] = True  # today's rule: the rerun's "" differs
    assert rerun.differences(new, _ev(rows)) == ["ekf.worse_than_measurements: True -> ''"]
