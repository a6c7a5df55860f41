"""A dataset id resolved once (:mod:`replay.data.dataset_ref`): what each kind of id becomes."""
from __future__ import annotations

from pathlib import Path

import pytest

from replay.data import dataset_ref, registry

from replay.run import pipeline
from replay.util.errors import ReplayError


def test_registered_simulator_recording_and_path(tmp_path):
    sim = dataset_ref.resolve("sim/auv-sonar")
    assert (sim.kind, sim.is_sim, sim.is_path, sim.sequence, sim.adapter) == ("sim", True, False, "auv-sonar", None)
    assert sim.entry is registry.get("sim/auv-sonar") and sim.target is sim.entry
    assert sim.locate() is None and sim.inputs(mapping="m.toml") == [Path("m.toml")]
    rec = dataset_ref.resolve("bohai/20220822_0_6")
    assert (rec.kind, rec.adapter, rec.sequence, rec.path) == ("file", "bohai-csv", "20220822_0_6", None)
    (tmp_path / "20220822_0_6.csv").write_text("x\n")
    assert rec.locate(tmp_path) == tmp_path / "20220822_0_6.csv"
    log = tmp_path / "log.csv"
    path = dataset_ref.resolve(str(log), adapter="lake")
    assert (path.kind, path.is_path, path.entry, path.path, path.adapter, path.target) == (
        "path", True, None, log, "lake", str(log))
    assert path.inputs(tmp_path / "elsewhere") == [log] and path.sequence == "log.csv"
    assert dataset_ref.resolve(path) is path  # handed down, not parsed again
    assert dataset_ref.resolve(registry.get("sim/ungm")).kind == "sim"
    assert [dataset_ref.simulated(d) for d in ("sim/ungm", "bohai/20220822_0_6", str(log), "nosuch/x", None)] == [
        True, False, False, False, False]


def test_unknown_id_is_one_line_with_close_matches():
    with pytest.raises(ReplayError, match=r"^unknown dataset 'sim/auv-sonr' \(did you mean sim/auv-sonar"):
        dataset_ref.resolve("sim/auv-sonr")


def test_pipeline_uses_the_same_rule(tmp_path):
    """One rule tells ids from paths: pipeline.resolve and is_sim agree with dataset_ref."""
    assert pipeline.resolve("sim/auv-sonar").id == "sim/auv-sonar" and pipeline.is_sim("sim/auv-sonar")
    assert pipeline.resolve(str(tmp_path / "x.mcap")) is None and not pipeline.is_sim(str(tmp_path / "x.bag"))
    assert not pipeline.is_sim("bohai/20220822_0_6")
    with pytest.raises(ReplayError, match="unknown dataset"):
        pipeline.resolve("nosuch/thing")
