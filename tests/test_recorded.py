"""Recorded estimates (issue 14): [estimates] of a mapping -> Frame.estimates -> leaderboard rows
``recorded:<name>`` through the one pipeline, in eval and campaigns; numbers asserted on a synthetic
MCAP whose estimates are the reference plus known offsets, and on the real bags."""
import csv
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from replay.adapters import bags
from replay.cli import main
from replay.trajectory.associate import associate_times as associate

REPO = Path(__file__).resolve().parents[1]
T0 = 1_700_000_000 * 10**9
N = 200  # 10 Hz, 20 s
OFFSET = np.array([0.3, -0.4, 0.0])  # |OFFSET| = 0.5
UTM19 = "EPSG:32619"


def _truth():
    t = np.arange(N) * 0.1
    p = np.column_stack([10 * np.cos(0.2 * t), 10 * np.sin(0.2 * t), 0.1 * t])
    yaw = 0.2 * t + np.pi / 2
    q = np.column_stack([np.zeros(N), np.zeros(N), np.sin(yaw / 2), np.cos(yaw / 2)])
    return (T0 + np.arange(N) * 10**8).astype(np.int64), p, q


def make_recording(path: Path) -> Path:
    """A standalone MCAP (ROS 2 CDR) with a reference and estimates of known errors."""
    from pyproj import Transformer

    from replay.adapters.bags import BagOut

    stamps, p, q = _truth()
    out = BagOut(path)
    T = out.T
    pose_st = lambda ns, frame, pos, quat: T["geometry_msgs/msg/PoseStamped"](
        header=out.header(ns, frame), pose=out.pose(pos, quat))
    conns = {name: out.connection(name, typ) for name, typ in [
        ("/truth", "geometry_msgs/msg/PoseStamped"), ("/slam", "geometry_msgs/msg/PoseStamped"),
        ("/ekf", "nav_msgs/msg/Odometry"), ("/amcl", "geometry_msgs/msg/PoseWithCovarianceStamped"),
        ("/lag", "geometry_msgs/msg/PoseStamped"), ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/path", "nav_msgs/msg/Path"), ("/rot", "geometry_msgs/msg/PoseStamped"),
        ("/late", "geometry_msgs/msg/PoseStamped"), ("/dup", "geometry_msgs/msg/PoseStamped"),
        ("/badq", "geometry_msgs/msg/PoseStamped"), ("/messy", "geometry_msgs/msg/PoseStamped"),
        ("/gps", "sensor_msgs/msg/NavSatFix"), ("/ins", "sensor_msgs/msg/NavSatFix")]}
    c30, s30 = np.cos(np.pi / 6), np.sin(np.pi / 6)
    R = np.array([[c30, -s30, 0], [s30, c30, 0], [0, 0, 1]])
    cov = np.diag([0.25, 0.25, 0.25, 0.1, 0.1, 0.1]).ravel()
    tr = Transformer.from_crs(UTM19, "EPSG:4326", always_xy=True)
    east, north = 323000.0 + p[:, 0], 4693000.0 + p[:, 1]
    lon, lat = tr.transform(east, north)
    lon2, lat2 = tr.transform(east + 3.0, north + 4.0)

    def fix(ns, la, lo):
        return T["sensor_msgs/msg/NavSatFix"](
            header=out.header(ns, "gps"), status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
            latitude=float(la), longitude=float(lo), altitude=20.0, position_covariance=np.diag([4.0, 4.0, 9.0]).ravel(),
            position_covariance_type=2)

    def tfm(ns, parent, child, pos, quat):
        return T["geometry_msgs/msg/TransformStamped"](
            header=out.header(ns, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=out.vec(pos), rotation=out.quat(quat)))

    for k in range(N):
        ns = int(stamps[k])
        w = lambda topic, msg, log=ns + 5 * 10**6: out.write(conns[topic], log, msg)
        w("/truth", pose_st(ns, "map", p[k], q[k]))
        w("/slam", pose_st(ns, "map", p[k] + OFFSET, q[k]))
        if k % 2 == 0:  # 5 Hz, stamped 3 ms after the reference samples
            w("/ekf", out.odometry(ns + 3 * 10**6, "map", "base", p[k] + OFFSET, q[k], [0, 0, 0], [0, 0, 0], cov))
            w("/amcl", T["geometry_msgs/msg/PoseWithCovarianceStamped"](
                header=out.header(ns, "map"), pose=T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=out.pose(p[k] + [1.0, 0, 0], q[k]), covariance=cov if k >= 20 else np.zeros(36))))
        w("/lag", pose_st(ns + 250 * 10**6, "map", p[k], q[k]))  # stamped 0.25 s late
        w("/tf", T["tf2_msgs/msg/TFMessage"](transforms=[
            tfm(ns, "map", "body", p[k] + [1.0, 0, 0], q[k]), tfm(ns, "map", "other", [5, 5, 5], [0, 0, 0, 1])]))
        w("/rot", pose_st(ns, "slam_map", R @ p[k] + [2.0, -1.0, 0.5], q[k]))
        w("/late", pose_st(ns + 1000 * 10**9, "map", p[k], q[k]))
        w("/dup", pose_st(ns if k != 7 else int(stamps[6]), "map", p[k], q[k]))
        w("/badq", pose_st(ns, "map", p[k], q[k] * (2.0 if k == 11 else 1.0)))
        messy = p[k] + OFFSET if k != 3 else [np.nan, 0, 0]
        w("/messy", pose_st(ns, "map", messy, q[k] * (1 + 1e-4 if k in (4, 5) else 1.0)))
        w("/gps", fix(ns, lat[k], lon[k]))
        w("/ins", fix(ns, lat2[k], lon2[k]))
    junk = T["nav_msgs/msg/Path"](header=out.header(int(stamps[0]), "map"),
                                  poses=[pose_st(int(stamps[0]), "map", [9, 9, 9], [0, 0, 0, 1])])
    out.write(conns["/path"], int(stamps[0]), junk)
    last = T["nav_msgs/msg/Path"](header=out.header(int(stamps[-1]), "map"),
                                  poses=[pose_st(int(s), "", pk + [0, 0, 2.0], qk) for s, pk, qk in zip(stamps, p, q)])
    out.write(conns["/path"], int(stamps[-1]) + 10**7, last)
    out.close()
    return next(path.glob("*.mcap"))


MAPPING = """
[reference]
position = "/truth"

[estimates]
slam = "/slam"
ekf = "/ekf"
amcl = "/amcl"
lag = { topic = "/lag", t_offset = -0.25 }
tf = { topic = "/tf", frame = "map", child = "body" }
path = "/path"
rot = { topic = "/rot", align = "se3" }
messy = "/messy"
"""


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    mcap = make_recording(d / "bag")
    m = d / "map.toml"
    m.write_text(MAPPING)
    return mcap, m


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def rows_of(out):
    with open(Path(out) / "leaderboard.csv") as fh:
        return {r["filter"]: r for r in csv.DictReader(fh)}


def results_of(out):
    """The rows at full precision (the manifest's results)."""
    return json.loads((Path(out) / "manifest.json").read_text())["results"]


def one_line_error(args, *words):
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 2, res.output
    err = res.output.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


# ---------------------------------------------------------------- association

def test_associate_as_evo():
    ref = np.array([0.0, 0.1, 0.2, 0.3, 0.4])
    est = np.array([0.004, 0.105, 0.35, 0.398])  # shorter: each of its stamps finds its nearest reference
    i, j = associate(ref, est, 0.01)
    assert i.tolist() == [0, 1, 4] and j.tolist() == [0, 1, 3]  # 0.35 is 0.05 from both: not within 0.01
    i, j = associate(ref, est, 0.06)
    assert i.tolist() == [0, 1, 3, 4] and j.tolist() == [0, 1, 2, 3]  # a tie goes to the earlier (evo: argmin)
    dense = np.arange(0, 0.5, 0.01) + 0.002  # longer estimate: each reference stamp finds its nearest pose
    i, j = associate(ref, dense, 0.01)
    assert i.tolist() == [0, 1, 2, 3, 4] and np.allclose(dense[j] - ref, 0.002)
    i, j = associate(ref, est - 1.0, 0.01, t_offset=1.0)
    assert i.tolist() == [0, 1, 4]
    assert [len(x) for x in associate(ref, np.zeros(0))] == [0, 0]


# ---------------------------------------------------------------- the frame

def test_frame_keeps_estimates_apart(rec):
    mcap, m = rec
    f = bags.load(mcap, mapping=m)
    assert len(f) == N and set(f.reference) >= {"position"} and not f.channels  # the axis: the reference only
    e = f.estimates
    assert list(e) == ["slam", "ekf", "amcl", "lag", "tf", "path", "rot", "messy"]
    assert len(e["slam"]) == N and len(e["ekf"]) == N // 2
    np.testing.assert_allclose(e["ekf"].t, f.t[::2] + 0.003, atol=1e-9)
    np.testing.assert_allclose(e["ekf"].covariance[0], 0.25 * np.eye(3))
    assert e["slam"].covariance is None and e["slam"].orientation.shape == (N, 4)
    assert e["ekf"].frame == "map" and e["ekf"].child == "base" and e["tf"].child == "body"
    assert np.isnan(e["amcl"].covariance[:10]).all() and np.isfinite(e["amcl"].covariance[10:]).all()
    np.testing.assert_allclose(e["path"].position[:, 2] - f.reference["position"].values[:, 2], 2.0)
    assert len(e["path"]) == N  # the last Path message, at its poses' own stamps
    assert len(e["messy"]) == N - 1
    assert f.report.find("dropped", "messy")[0].count == 1
    assert f.report.find("repaired", "messy")[0].count == 2
    assert f.report.find("masked", "amcl_covariance")[0].count == 10
    assert f.meta["estimates"]["ekf"]["covariance"] and f.meta["estimates"]["lag"]["params"] == {"t_offset": -0.25}
    g = f.head(50)
    assert len(g.estimates["slam"]) == 50 and len(g.estimates["ekf"]) == 25 and g.estimates["slam"].t[-1] == g.t[-1]


# ---------------------------------------------------------------- numbers through replay eval

def test_known_offsets_give_their_rmse(rec, tmp_path):
    mcap, m = rec
    res = cli("eval", mcap, "--mapping", m, "--filters", "none", "--runs", "3", "-o", tmp_path / "o")
    assert res.exit_code == 0, res.output
    assert "recorded:slam: 200 of its 200 poses associated with 200 reference samples" in res.output
    r = rows_of(tmp_path / "o")
    assert list(r) == [f"recorded:{k}" for k in ("slam", "ekf", "amcl", "lag", "tf", "path", "rot", "messy")]
    slam = r["recorded:slam"]
    assert float(slam["pos_rmse"]) == pytest.approx(0.5, abs=1e-12)
    assert float(slam["x_rmse"]) == pytest.approx(0.3, abs=1e-12)
    assert float(slam["y_rmse"]) == pytest.approx(0.4, abs=1e-12)
    assert float(slam["z_rmse"]) == pytest.approx(0.0, abs=1e-12)
    assert float(slam["final_err"]) == pytest.approx(0.5, abs=1e-12)
    assert float(slam["ate"]) < 1e-9  # a pure translation: SE(3) alignment removes it
    assert slam["runs"] == "1" and slam["scored"] == "200" and slam["lost"] == "0"  # one run whatever --runs
    assert json.loads(slam["params"]) == {"align": "none", "t_max_diff": 0.01, "t_offset": 0.0}
    ekf = r["recorded:ekf"]  # 3 ms after the reference stamps, covariance 0.25 I: NEES = 0.25 / 0.25 = 1
    assert float(ekf["pos_rmse"]) == pytest.approx(0.5, abs=1e-12) and ekf["scored"] == "100"
    assert float(ekf["nees"]) == pytest.approx(1.0, abs=1e-12) and float(ekf["anees"]) == pytest.approx(1.0, abs=1e-12)
    amcl = r["recorded:amcl"]  # error 1 m along x; covariance unknown on its first 10 poses
    assert float(amcl["pos_rmse"]) == pytest.approx(1.0, abs=1e-12) and float(amcl["nees"]) == pytest.approx(4.0)
    for name, want in (("lag", 0.0), ("tf", 1.0), ("path", 2.0), ("rot", 0.0), ("messy", 0.5)):
        assert float(r[f"recorded:{name}"]["pos_rmse"]) == pytest.approx(want, abs=1e-9), name
    assert r["recorded:messy"]["scored"] == "199"
    assert float(r["recorded:slam"]["pos_rmse_vs_recorded:slam"] or 0) == 0.0
    assert float(r["recorded:tf"]["pos_rmse_vs_recorded:slam"]) == pytest.approx(0.5, abs=1e-9)
    man = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert man["config"]["filters"][0] == "recorded:slam" and "--filters recorded:slam,recorded:ekf" in man["command"]
    res = cli("rerun", tmp_path / "o" / "manifest.json")
    assert res.exit_code == 0 and "reproduced" in res.output, res.output


@pytest.mark.slow
def test_beside_filters_choose_and_override(rec, tmp_path):
    mcap, m = rec
    res = cli("eval", mcap, "--mapping", m, "--filters", "ekf,recorded:slam,recorded:rot", "--runs", "2",
              "--first", "100", "-p", "recorded:rot.align=none", "-o", tmp_path / "a")
    assert res.exit_code == 0, res.output
    r = rows_of(tmp_path / "a")
    assert list(r) == ["ekf", "measurements", "recorded:slam", "recorded:rot"]  # position: the raw observations too
    assert r["ekf"]["runs"] == "2" and r["recorded:slam"]["runs"] == "1"
    assert float(r["recorded:rot"]["pos_rmse"]) > 2.0  # raw: another frame
    assert float(r["recorded:rot"]["ate"]) < 1e-9  # aligned
    assert r["recorded:slam"]["pos_rmse_vs_ekf"] != ""  # paired on run 0
    res = cli("eval", mcap, "--mapping", m, "--filters", "ekf,recorded:none", "--first", "20", "-o", tmp_path / "b")
    assert res.exit_code == 0 and list(rows_of(tmp_path / "b")) == ["ekf", "measurements"]


def test_navsatfix_estimate_projected_like_the_fixes(rec, tmp_path):
    mcap, _ = rec
    m = tmp_path / "gps.toml"
    m.write_text('[reference]\nposition = "/gps"\n[estimates]\nins = "/ins"\n')
    f = bags.load(mcap, mapping=m)
    assert f.meta["crs"] == UTM19
    np.testing.assert_allclose(f.estimates["ins"].position[:, :2] - f.reference["position"].values[:, :2],
                               np.tile([3.0, 4.0], (N, 1)), atol=1e-6)
    np.testing.assert_allclose(f.estimates["ins"].covariance[0], np.diag([4.0, 4.0, 9.0]))
    res = cli("eval", mcap, "--mapping", m, "--filters", "none", "-o", tmp_path / "o")
    assert res.exit_code == 0, res.output
    row = rows_of(tmp_path / "o")["recorded:ins"]
    assert float(row["pos_rmse"]) == pytest.approx(5.0, abs=1e-6)
    assert float(row["nees"]) == pytest.approx(9 / 4 + 16 / 4, rel=1e-6)


def test_campaign_rows_equal_eval(rec, tmp_path):
    mcap, m = rec
    camp = tmp_path / "c.toml"
    camp.write_text(f'[campaign]\nname = "rec"\nruns = 3\n\n[[dataset]]\nid = "{mcap}"\n'
                    f'params = {{ mapping = "{m}" }}\nrecorded = ["slam", "ekf"]\n')
    res = cli("campaign", "run", camp, "--out", tmp_path / "c", "--workers", "1")
    assert res.exit_code == 0, res.output
    board = rows_of(tmp_path / "c")
    assert list(board) == ["recorded:slam", "recorded:ekf"]
    res = cli("eval", mcap, "--mapping", m, "--filters", "recorded:slam,recorded:ekf", "--runs", "3", "-o", tmp_path / "e")
    assert res.exit_code == 0, res.output
    ev = rows_of(tmp_path / "e")
    for name in board:
        for k in ("pos_rmse", "x_rmse", "ate", "final_err", "nees", "scored", "runs", "config_hash"):
            assert board[name][k] == ev[name][k], (name, k)
    units = sorted(p.name for p in (tmp_path / "c" / "units" / board["recorded:slam"]["config_hash"]).iterdir())
    assert [u for u in units if u.endswith(".parquet")] == ["0.parquet"]  # one unit: run 0


def test_campaign_tables_show_a_recording_as_its_file_writes_it(rec, tmp_path):
    """A recording's id relative to the campaign file is shown so in every table (the printed one,
    leaderboard.csv, paired.csv, replay leaderboard, the report's sections), never as a machine's
    path; the configurations keep the absolute path that computing a unit again needs."""
    import shutil

    from replay.campaign import index
    from replay.outputs import report_data

    mcap, m = rec
    shutil.copytree(mcap.parent, tmp_path / "camp" / "data")
    shutil.copy(m, tmp_path / "camp" / "map.toml")
    written = f"data/{mcap.name}"
    camp = tmp_path / "camp" / "c.toml"
    camp.write_text(f'[campaign]\nruns = 2\n\n[[dataset]]\nid = "{written}"\n'
                    'params = { mapping = "map.toml" }\nrecorded = ["slam", "ekf"]\n')
    res = cli("campaign", "run", camp, "--out", tmp_path / "c", "--workers", "1")
    assert res.exit_code == 0, res.output
    board = rows_of(tmp_path / "c")
    assert [r["dataset"] for r in board.values()] == [written, written]
    assert float(board["recorded:slam"]["pos_rmse"]) > 0
    paired = (tmp_path / "c" / "paired.csv").read_text()
    assert f"\n{written},position,recorded:slam,recorded:ekf," in paired
    shown = cli("leaderboard", tmp_path / "c")
    assert shown.exit_code == 0 and written in shown.output
    for text in (res.output, paired, (tmp_path / "c" / "leaderboard.csv").read_text(), shown.output):
        assert str(tmp_path / "camp") not in text  # the recording's machine path in no table
    assert [(s.dataset, len(s.paired)) for s in report_data.load(tmp_path / "c")] == [(written, 2)]
    configs, _, problem = index.read(tmp_path / "c")
    assert problem is None and {c["dataset"] for c in configs.values()} == {str(tmp_path / "camp" / written)}
    assert index.names(tmp_path / "c") == {str(tmp_path / "camp" / written): written}


# ---------------------------------------------------------------- refusals: one line, file and topic

REFUSALS = [
    ('[estimates]\nx = "/nope"\n', ["topic /nope (mapped to estimate x) is not in the recording"]),
    ('[estimates]\nx = "/late"\n', ["estimate x (topic /late)", "do not overlap the reference"]),
    ('[estimates]\nx = "/dup"\n', ["topic /dup", "non-increasing header stamps at message 7", "duplicate stamp"]),
    ('[estimates]\nx = "/badq"\n', ["estimate x (topic /badq)", "non-unit quaternion at message 11", "norm 2"]),
    ('[estimates]\nx = "/lag"\n', ["recorded estimate x (/lag", "0 pose(s) associated", "t_max_diff 0.01 s"]),
    ('[estimates]\nx = "/tf"\n', ["topic /tf (mapped to x)", "name the pair", "map -> body (200)"]),
    ('[estimates]\nx = { topic = "/tf", frame = "map", child = "nope" }\n', ["/tf", "no transform map -> nope"]),
    ('[estimates]\nx = { topic = "/slam", type = "sensor_msgs/msg/Imu" }\n', ["map.toml", "is not a trajectory"]),
    ('[estimates]\nx = { topic = "/slam", t_max_diff = -1 }\n', ["map.toml", "t_max_diff must be"]),
    ('[estimates]\n"a/b" = "/slam"\n', ["map.toml", "a name of letters"]),
    ('[estimates]\nx = { topic = "/slam", frame = "map" }\n', ["map.toml", "needs both frame"]),
]


@pytest.mark.parametrize("extra,words", REFUSALS, ids=[w[0] for _, w in REFUSALS])
def test_bad_estimates_refused_in_one_line(rec, tmp_path, extra, words):
    mcap, _ = rec
    m = tmp_path / "map.toml"
    m.write_text('[reference]\nposition = "/truth"\n' + extra)
    err = one_line_error(["eval", mcap, "--mapping", m, "--filters", "none", "-o", tmp_path / "o"], *words)
    assert str(mcap) in err or "map.toml" in err


def test_tf_only_recording(tmp_path):
    from replay.adapters.bags import BagOut

    stamps, p, q = _truth()
    out = BagOut(tmp_path / "tf")
    T, c = out.T, out.connection("/tf", "tf2_msgs/msg/TFMessage")
    tr = lambda ns, child, pos: T["geometry_msgs/msg/TransformStamped"](
        header=out.header(ns, "/map"), child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](translation=out.vec(pos), rotation=out.quat([0, 0, 0, 1])))
    for k in range(50):
        out.write(c, int(stamps[k]), T["tf2_msgs/msg/TFMessage"](transforms=[
            tr(int(stamps[k]), "body", p[k]), tr(int(stamps[k]) + 2 * 10**6, "slam", p[k] + [0.0, 0.0, 0.7])]))
    out.close()
    mcap = next((tmp_path / "tf").glob("*.mcap"))
    one_line_error(["eval", mcap, "-o", tmp_path / "o"], str(mcap), "/tf hold(s) TF: name a pair")
    m = tmp_path / "tf.toml"
    m.write_text('[reference]\nposition = { topic = "/tf", frame = "map", child = "body" }\n'
                 '[estimates]\nslam = { topic = "/tf", frame = "map", child = "slam" }\n')
    res = cli("eval", mcap, "--mapping", m, "--filters", "none", "-o", tmp_path / "o")
    assert res.exit_code == 0, res.output
    row = results_of(tmp_path / "o")["recorded:slam"]  # 2 ms after the reference, 0.7 m above it
    assert row["pos_rmse"] == pytest.approx(0.7, abs=1e-12) and row["scored"] == 50


def test_bad_names_refused(rec, tmp_path):
    mcap, m = rec
    one_line_error(["eval", mcap, "--mapping", m, "--filters", "recorded:nope", "-o", tmp_path / "o"],
                   "no recorded estimate 'nope'", "slam, ekf")
    one_line_error(["eval", mcap, "--mapping", m, "--filters", "none", "-p", "recorded:slam.t_max_diff=x",
                    "-o", tmp_path / "o"], "t_max_diff")
    one_line_error(["eval", mcap, "--mapping", m, "--filters", "none,ekf", "-o", tmp_path / "o"], "'none'")
    m2 = tmp_path / "m2.toml"
    m2.write_text('[reference]\nposition = "/truth"\n')
    one_line_error(["eval", mcap, "--mapping", m2, "--filters", "none", "-o", tmp_path / "o"], "nothing to score")


# ---------------------------------------------------------------- real recordings

@pytest.fixture(scope="module")
def bagdir(shared_dir):
    path = shared_dir / "datasets" / "bags"
    if not path.is_dir():
        pytest.skip(f"{path} missing (shared datasets)")
    return path


@pytest.mark.slow
def test_ros_example_orb_slam_and_sptam_as_evo(bagdir, tmp_path):
    res = cli("eval", bagdir / "evo/ROS_example.bag", "--mapping", REPO / "docs/mappings/evo_ros_example.toml",
              "--filters", "none", "-o", tmp_path / "o")
    assert res.exit_code == 0, res.output
    assert "recorded:ORB-SLAM" in res.output and "recorded:S-PTAM" in res.output
    r = results_of(tmp_path / "o")
    orb, spt = r["recorded:ORB-SLAM"], r["recorded:S-PTAM"]
    # evo_ape bag ROS_example.bag groundtruth ORB-SLAM -a: rmse 5.509938 (2550 pairs); without -a: 8.508008
    # the mapping declares align = "se3" (SLAM in its own frame): every column is of the aligned track
    assert float(orb["ate"]) == pytest.approx(5.509938, abs=1e-6) and orb["scored"] == 2550
    assert float(orb["pos_rmse"]) == pytest.approx(5.509938, abs=1e-6)
    assert float(orb["pos_rmse_unaligned"]) == pytest.approx(8.508008, abs=1e-6)
    assert orb["lost"] == 0 and orb["lost_unaligned"] == 1  # aligned-good: not lost; as recorded: off by > 10 m
    # evo_ape bag ROS_example.bag groundtruth S-PTAM: rmse 10.344660 (1667 pairs); with -a 6.316710
    assert float(spt["pos_rmse_unaligned"]) == pytest.approx(10.344660, abs=1e-6) and spt["scored"] == 1667
    assert float(spt["ate"]) == pytest.approx(6.316710, abs=1e-6)
    assert float(spt["pos_rmse"]) == pytest.approx(6.316710, abs=1e-6)
    assert any(x.split()[:4] == ["filter", "pos_rmse", "median", "ate"] for x in res.output.splitlines())


@pytest.mark.slow
def test_ros_example_first_samples(bagdir, tmp_path):
    res = cli("eval", bagdir / "evo/ROS_example.bag", "--mapping", REPO / "docs/mappings/evo_ros_example.toml",
              "--filters", "none", "--first", "2000", "-o", tmp_path / "o")
    assert res.exit_code == 0, res.output
    r = results_of(tmp_path / "o")  # the first 2000 ground-truth samples (119.9 s)
    assert float(r["recorded:ORB-SLAM"]["pos_rmse_unaligned"]) == pytest.approx(1.33449152683659, rel=1e-9)
    assert float(r["recorded:ORB-SLAM"]["ate"]) == pytest.approx(0.628130603751518, rel=1e-9)
    assert float(r["recorded:ORB-SLAM"]["pos_rmse"]) == pytest.approx(0.628130603751518, rel=1e-9)
    assert r["recorded:ORB-SLAM"]["scored"] == 372
    assert float(r["recorded:S-PTAM"]["pos_rmse_unaligned"]) == pytest.approx(1.802266407596184, rel=1e-9)


def test_rl_recorded_odometry_against_held_out_fixes(bagdir, tmp_path):
    res = cli("eval", bagdir / "derived/rl_test1_60s_mcap", "--mapping", REPO / "docs/mappings/rl_test1_recorded.toml",
              "--task", "gps-odom", "--filters", "none", "-o", tmp_path / "o")
    assert res.exit_code == 0, res.output
    row = results_of(tmp_path / "o")["recorded:wheel_odom"]
    assert row["task"] == "gps-odom" and row["scored"] == 56  # of the 120 held-out fixes (150 less every 5th)
    assert row["pos_rmse"] == pytest.approx(1.83343, abs=1e-5)  # after the se3 fit of the mapping
    assert row["anees"] > 100  # its recorded covariance (0.001 m^2) is far too small


@pytest.mark.slow
def test_tf_only_reference_nav2(bagdir, tmp_path):
    m = tmp_path / "nav2.toml"
    m.write_text('[reference]\nposition = { topic = "/tf", frame = "odom", child = "base_link" }\n'
                 '[estimates]\nodom = "/odom"\n')
    f = bags.load(bagdir / "evo/nav2_turtlebot.mcap", mapping=m)
    assert len(f) == 2639 and f.meta["sim_time"]
    res = cli("eval", bagdir / "evo/nav2_turtlebot.mcap", "--mapping", m, "--filters", "none", "-o", tmp_path / "o")
    assert res.exit_code == 0, res.output
    row = rows_of(tmp_path / "o")["recorded:odom"]
    assert float(row["pos_rmse"]) == 0.0 and row["scored"] == "2639"  # /odom is the odom -> base_link transform
