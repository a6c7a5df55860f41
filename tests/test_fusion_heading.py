"""An attitude angle no fused input measures (issue 34, item 5; replay/tasks/fusion_heading.py).

When nothing measures the heading absolutely and the declared model's uncertainty on it grows past the
1 % shrink, the table and the manifest say so in one line naming the angle, its sd and the factor
exp(-sd^2/2) by which a posterior-mean estimator (the PF) lies inside the arc; fused with an attitude or
an absolute position, or declared known, they do not. The sd is the EKF's own, to rounding."""

import math
import re

import numpy as np
import pytest
from odom_recordings import mapping, write_odometry_bag

import replay
from replay.outputs.files import format_table
from replay.run.manifest import manifest
from replay.tasks.fusion_heading import SHRINK_LIMIT, angle_sd

VR = 'fuse = ["velocity", "rate"]'
LINE = re.compile(
    r"^(?P<angle>heading \(yaw\)|roll|pitch) unconstrained: no fused input measures it absolutely \(inputs: "
    r"(?P<inputs>[^)]*(?:\(differential\)[^)]*)*)\); the declared model's sd of it reaches (?P<sd>[0-9.]+) rad at "
    r"the end .*a posterior-mean estimator \(pf\) lies inside the arc by exp\(-sd\^2/2\) = (?P<f>[0-9.e-]+), so "
    r"its distance to a dead-reckoned track is no filter defect; the Kalman rows give f\(mean\)$"
)


def evaluate(tmp_path, fuse=VR, dims=2, filters=("ekf",), **kw):
    bag = tmp_path / f"b{dims}"
    if not bag.exists():
        write_odometry_bag(bag, dims=dims)
    mp = mapping(tmp_path / f"m{abs(hash((fuse, dims)))}.toml", fuse=fuse, extra=kw.pop("extra", ""))
    return replay.evaluate(str(bag), dataset_params={"mapping": str(mp)}, filters=list(filters), task="fusion",
                           recorded=(), task_params={"dims": str(dims), **kw.pop("task_params", {})}, **kw)


def lines(ev):
    return (ev.frame_meta["reference"] or {}).get("unconstrained", [])


@pytest.mark.parametrize("fuse", [VR, 'differential = ["position", "attitude"]'])
def test_unconstrained_heading_said_on_the_table_and_in_the_manifest(tmp_path, fuse):
    """Generated odometry (60 s, 102 m, twist variances the task's defaults): the heading's sd reaches
    0.95 rad (velocity + rate) and 0.79 rad (differential: the derived rate's variance), the EKF's own."""
    ev = evaluate(tmp_path, fuse)
    (line,) = lines(ev)
    got = LINE.match(line)
    assert got and got["angle"] == "heading (yaw)", line
    pb = ev.results[0].records[0]["problem"]
    P = ev.results[0].estimates[0].P
    sd = angle_sd(pb.model, pb.z, pb.P0, 2, 5)
    np.testing.assert_allclose(sd, np.sqrt(P[:, 2, 2]), rtol=1e-8)  # the EKF's heading sd at every step
    assert float(got["sd"]) == pytest.approx(sd[-1], abs=0.005) and 0.7 < sd[-1] < 1.0
    assert float(got["f"]) == pytest.approx(math.exp(-sd[-1] ** 2 / 2), rel=1e-3)
    assert ("(differential)" in got["inputs"]) == fuse.startswith("differential")
    assert line in format_table(ev).splitlines()  # on the table, under the reference's lines
    assert manifest(ev)["dataset"]["reference"]["unconstrained"] == [line]


def test_no_line_when_the_heading_is_measured_or_known(tmp_path):
    """An attitude input, an absolute position (the course between fixes), or a declared model whose
    heading stays within the 1 % shrink (sd 0.02 rad after 60 s): no line, and none on the table."""
    for fuse in ('fuse = ["velocity", "rate", "attitude"]', 'fuse = ["position", "velocity", "rate"]'):
        ev = evaluate(tmp_path, fuse)
        assert lines(ev) == [] and "unconstrained" not in format_table(ev)
        assert "unconstrained" not in manifest(ev)["dataset"]["reference"]
    known = {"q_attitude": 1e-6, "r_velocity": 1e-4, "r_rate": 1e-6, "p0_known": 1e-4}
    ev = evaluate(tmp_path, extra=", noise = { velocity = 1e-4, rate = 1e-6 }", task_params=known)
    pb = ev.results[0].records[0]["problem"]
    sd = angle_sd(pb.model, pb.z, pb.P0, 2, 5)[-1]
    assert 1 - math.exp(-(sd**2) / 2) < SHRINK_LIMIT and sd < 0.03 and lines(ev) == []


def test_3d_names_each_angle_nothing_measures(tmp_path):
    """3-D odometry twist alone: roll, pitch and yaw are each integrated from their rate only."""
    ev = evaluate(tmp_path, dims=3)
    got = [LINE.match(line) for line in lines(ev)]
    assert all(got) and [g["angle"] for g in got] == ["roll", "pitch", "heading (yaw)"]
    assert all(0.7 < float(g["sd"]) < 1.2 for g in got)
    ev = evaluate(tmp_path, 'fuse = ["velocity", "rate", "attitude"]', dims=3)
    assert lines(ev) == []
