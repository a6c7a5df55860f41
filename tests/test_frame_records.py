"""The frame's typed records (issue 37, item 4): how a simulator made the frame, its maneuvers, the
columns of its channels and its default task are fields of the frame, not ``meta`` keys; a task reads
its inputs from channels and records, never from ``frame.meta`` (metadata only)."""
from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import replay
from replay.data import registry
from replay.scoring.scorer import within
from replay.tasks import make_task
from replay.util.errors import ReplayError

ROOT = Path(__file__).resolve().parents[1]


def test_a_simulators_parameters_ride_on_the_frame_as_its_validated_record():
    frame = registry.load_frame("sim/ungm", rng=np.random.default_rng(0), q=10.0, steps=7)
    sim = frame.simulation
    assert sim.generator == "replay.sim.ungm" and (sim.params.q, sim.params.r, sim.params.growth) == (10.0, 1.0, 2.5)
    assert (sim.dt, sim.initial_state, sim.state) == (1.0, (0.0,), ("x",))
    assert not {"q", "r", "growth", "dt", "initial_state"} & frame.meta.keys()
    with pytest.raises(dataclasses.FrozenInstanceError):
        sim.params.q = 1.0
    sonar = registry.load_frame("sim/auv-sonar", rng=np.random.default_rng(0), steps=3, yaw_rate=0.1)
    assert sonar.simulation.params.yaw_rate == 0.1 and sonar.simulation.state == ("x", "y", "z", "v", "pitch", "yaw")
    assert sonar.simulation.initial_state == pytest.approx((0, 0, 0, 10, np.pi / 4, np.pi / 10))
    # the manifest's "dataset" section keeps them, as plain values
    ev = replay.evaluate("sim/ungm", filters=["ekf"], runs=1, dataset_params={"steps": 5, "r": 2.0})
    rec = ev.frame_meta["simulation"]
    assert rec["generator"] == "replay.sim.ungm" and rec["params"]["r"] == 2.0 and rec["initial_state"] == [0.0]


def test_a_views_cut_moves_the_maneuvers_with_the_time_axis():
    whole = registry.load_frame("sim/lake-depth", rng=np.random.default_rng(0))
    cut = registry.load_frame("sim/lake-depth", rng=np.random.default_rng(0), window="20:")
    offset = cut.meta["view"]["offset_s"]
    assert offset == pytest.approx(20.0) and cut.t[0] == 0.0
    assert cut.maneuvers == tuple((a - 20.0, b - 20.0, label) for a, b, label in whole.maneuvers)  # each moved
    assert cut.maneuvers[0] == (-10.0, 3.5, "dive")  # the dive began before the cut: its end is kept
    short = registry.load_frame("sim/lake-depth", rng=np.random.default_rng(0), window="25:60")
    assert [m[2] for m in short.maneuvers] == ["pitch steps, climb"]  # the dives wholly outside are left out
    inside = within(cut.t, cut.maneuvers)
    assert inside.any() and not inside.all()
    assert np.array_equal(inside, within(cut.t + offset, whole.maneuvers))  # the same samples, before and after
    assert whole.head(300).maneuvers == ((10.0, 23.5, "dive"),)  # 15 s: the dive only


def test_a_task_refuses_a_setting_the_simulator_did_not_declare():
    linear = registry.load_frame("sim/linear", rng=np.random.default_rng(0), steps=5)
    assert linear.simulation.params.q == 0.3 and linear.simulation.initial_state is None
    with pytest.raises(ReplayError, match=r"^task ungm: needs the simulator's growth, which replay\.sim\.linear does "
                                          r"not declare; give it as a task parameter$"):
        make_task("ungm").build(linear, np.random.default_rng(0))
    with pytest.raises(ReplayError, match=r"^task ungm: needs a simulated initial state \(x\); replay\.sim\.linear "
                                          r"has none$"):
        make_task("ungm", growth=2.5).build(linear, np.random.default_rng(0))


def test_tasks_read_no_input_from_frame_meta():
    """Every ``meta[...]`` / ``meta.get(...)`` in the built-in tasks names metadata used in messages."""
    allowed = {"source", "path", "dataset"}
    read = {}
    for path in sorted((ROOT / "replay" / "tasks").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            target = key = None
            if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
                target, key = node.value, node.slice.value
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
                  and node.args and isinstance(node.args[0], ast.Constant)):
                target, key = node.func.value, node.args[0].value
            if isinstance(target, ast.Attribute) and target.attr == "meta" or isinstance(target, ast.Name) and (
                    target.id == "meta"):
                read.setdefault(key, []).append(path.name)
    assert read and set(read) <= allowed, {k: v for k, v in read.items() if k not in allowed}
