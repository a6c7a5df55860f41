"""``replay convert``: every format written and read back gives the numbers written."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from replay.cli.main import main
from replay.trajectory import io
from replay.trajectory.base import make
from replay.trajectory.stamps import of_floats as ns
from replay.trajectory.files import write_tum


@pytest.fixture
def src(tmp_path):
    rng = np.random.default_rng(3)
    n = 200
    t = 1.6e9 + np.cumsum(rng.uniform(0.05, 0.15, n))  # Unix time, uneven steps
    p = np.cumsum(rng.normal(0, 0.3, (n, 3)), axis=0) + [1234.5678901234, -98.7654321, 3.14159265358979]
    q = Rotation.from_rotvec(rng.normal(0, 1.0, (n, 3))).as_quat()
    tr = make(t, p, q, source="src")
    write_tum(tmp_path / "src.tum", tr)  # %.17g: read back exactly
    return tmp_path, io.load(str(tmp_path / "src.tum"))


def run(*args):
    return CliRunner().invoke(main, ["convert", *map(str, args)], catch_exceptions=False)


@pytest.mark.parametrize("name, fmt", [("o.tum", None), ("o.txt", None), ("o.kitti", None), ("o.csv", None),
                                       ("o_euroc.csv", "euroc"), ("o.mcap", None)])
def test_round_trip(src, name, fmt):
    d, tr = src
    out = d / name
    r = run(d / "src.tum", out, *(["--format", fmt] if fmt else []))
    assert r.exit_code == 0, r.output
    assert r.output.startswith(f"200 poses of src.tum -> {out}")
    back = io.load(f"{out}:/pose" if name.endswith(".mcap") else str(out), fmt=fmt)
    assert len(back) == len(tr)
    if fmt == "euroc" or name.endswith(".mcap"):  # integer nanoseconds: the source's text, to the ns
        exact = io.load(f"{out}:/pose" if name.endswith(".mcap") else str(out), fmt=fmt, exact=True)
        assert np.array_equal(exact.ns, io.load(str(d / "src.tum"), exact=True).ns)
        assert np.abs(back.t - tr.t).max() <= 5e-10 + np.spacing(tr.t).max()  # one ulp at 1.6e9 s: 2.4e-7 s
    else:
        assert np.array_equal(back.t, tr.t)
    assert np.array_equal(back.p, tr.p)  # positions written in full
    tol = 1e-12 if name.endswith(".kitti") else 1e-15  # rotation matrices; quaternions normalised on reading
    sign = np.sign(np.sum(back.q * tr.q, axis=1))[:, None]  # KITTI: q and -q are one rotation
    assert np.abs(back.q * (sign if name.endswith(".kitti") else 1) - tr.q).max() <= tol
    if name.endswith((".tum", ".txt", ".csv")) and fmt is None:  # the digits written are the numbers
        m = np.loadtxt(out, comments="#", delimiter="," if name.endswith(".csv") else None, skiprows=int(
            name.endswith(".csv")))
        assert np.array_equal(m, np.column_stack([tr.t, tr.p, tr.q]))


def test_kitti_writes_times_beside(src):
    d, tr = src
    (d / "k").mkdir()
    r = run(d / "src.tum", d / "k" / "poses.kitti")
    assert r.exit_code == 0 and "stamps in" in r.output, r.output
    assert np.array_equal(np.loadtxt(d / "k" / "times.txt"), tr.t)


def test_recording_topic_source_and_chain(src):
    d, tr = src
    assert run(d / "src.tum", d / "a.mcap", "--topic", "/slam/pose", "--frame-id", "odom").exit_code == 0
    r = run(f"{d}/a.mcap:/slam/pose", d / "b.csv")
    assert r.exit_code == 0, r.output
    back = io.load(str(d / "b.csv"))
    assert np.array_equal(back.p, tr.p) and np.array_equal(ns(back.t), ns(tr.t))


def test_positions_only_as_csv_only(tmp_path):
    (tmp_path / "fix.csv").write_text("t,x,y,z\n" + "".join(f"{k}.25,{k * 1.5},{-k},0.125\n" for k in range(10)))
    r = run(tmp_path / "fix.csv", tmp_path / "out.csv")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "out.csv").read_text().splitlines()[:2] == ["t,x,y,z", "0.25,0.0,0.0,0.125"]
    r = CliRunner().invoke(main, ["convert", str(tmp_path / "fix.csv"), str(tmp_path / "out.tum")])
    assert r.exit_code == 2 and "positions only" in r.output and not (tmp_path / "out.tum").exists()


def test_tf_source(tmp_path, src):
    """RECORDING:tf:PARENT,CHILD converted: the file holds the transform replay score reads there."""
    from replay.adapters.bags import BagOut

    _, tr = src
    out = BagOut(tmp_path / "bag")
    T = out.T
    tf = out.connection("/tf", "tf2_msgs/msg/TFMessage")
    for k, stamp in enumerate(ns(tr.t[:50]).tolist()):
        out.write(tf, stamp, T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
            header=out.header(stamp, "odom"), child_frame_id="base_link",
            transform=T["geometry_msgs/msg/Transform"](translation=out.vec(tr.p[k]), rotation=out.quat(tr.q[k])))]))
    out.close()
    spec = f"{tmp_path / 'bag'}:tf:odom,base_link"
    r = run(spec, tmp_path / "tf.tum")
    assert r.exit_code == 0 and r.output.startswith("50 poses of bag:tf:odom,base_link"), r.output
    back, want = io.load(str(tmp_path / "tf.tum")), io.load(spec)
    assert np.array_equal(back.t, want.t) and np.array_equal(back.p, want.p) and np.array_equal(back.p, tr.p[:50])
    assert np.abs(back.q - want.q).max() <= 1e-15
