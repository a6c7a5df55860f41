"""evo's trajectory options of ``replay score`` (replay/trajectory/prepare.py), on constructed cases with
known answers: time window, interpolated association, downsampling, motion filter, projection."""
import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import replay
from replay.cli import main
from replay.trajectory.base import Trajectory


def _line(n, dt, t0=0.0, v=(1.0, 0.5, 0.0), z=0.0):
    t = t0 + dt * np.arange(n)
    p = np.c_[v[0] * t, v[1] * t, np.full(n, z) + v[2] * t]
    return Trajectory(t, p, name="tr")


def _ape(res):
    return res.stats().set_index("metric").loc["ape", "rmse"]


def test_window_keeps_the_poses_between_t_start_and_t_end():
    ref, est = _line(100, 0.1), _line(100, 0.1)
    r = replay.score(ref, est, t_start=2.0, t_end=4.95)
    assert r["tr"].reference.t[0] == pytest.approx(2.0) and len(r["tr"].reference) == 30


def test_interpolation_pairs_the_same_instant():
    ref = _line(1000, 0.01)  # 100 Hz
    est = _line(100, 0.1, t0=0.004)  # 10 Hz, 4 ms after a reference sample: within t_max_diff
    speed = np.hypot(1.0, 0.5)
    near = replay.score(ref, est)
    assert _ape(near) == pytest.approx(0.004 * speed, rel=1e-9)  # the nearest sample is 4 ms away
    interp = replay.score(ref, est, sync_method="interpolation")
    assert _ape(interp) < 1e-12 and len(interp["tr"].reference) == 100
    np.testing.assert_allclose(interp["tr"].reference.t, est.t)


def test_downsample_keeps_evenly_spaced_pairs():
    ref, est = _line(200, 0.1), _line(200, 0.1)
    r = replay.score(ref, est, downsample=20)
    np.testing.assert_array_equal(r["tr"].reference.t, ref.t[np.linspace(0, 199, 20).astype(int)])
    np.testing.assert_array_equal(r["tr"].estimate.t, r["tr"].reference.t)


def test_motion_filter_drops_standing_still():
    t = 0.1 * np.arange(40)
    x = np.r_[np.arange(10.0), np.full(20, 9.0), 9.0 + np.arange(1.0, 11.0)]  # moves, stands, moves
    ref = Trajectory(t, np.c_[x, np.zeros(40), np.zeros(40)], name="gt")
    est = Trajectory(t, np.c_[x, np.zeros(40), np.zeros(40)] + [0.0, 0.2, 0.0], name="est")
    r = replay.score(ref, est, motion_filter=(0.5, 180.0))
    kept = r["est"].reference.t
    assert len(kept) == 20 and not np.any((kept > 0.95) & (kept < 2.95))  # only the first standing pose kept
    np.testing.assert_array_equal(r["est"].estimate.t, kept)


def test_project_to_plane_drops_the_axis():
    ref, est = _line(50, 0.1), _line(50, 0.1, z=5.0)
    assert _ape(replay.score(ref, est)) == pytest.approx(5.0)
    assert _ape(replay.score(ref, est, project_to_plane="xy")) < 1e-12
    assert _ape(replay.score(ref, est, project_to_plane="xz")) == pytest.approx(5.0)


def test_cli_and_api_agree(tmp_path):
    ref, est = _line(1000, 0.01), _line(100, 0.1, t0=0.004, z=0.3)
    for tr, name in ((ref, "gt.tum"), (est, "est.tum")):
        q = np.tile([0.0, 0.0, 0.0, 1.0], (len(tr.t), 1))
        np.savetxt(tmp_path / name, np.c_[tr.t, tr.p, q], fmt="%.9f")
    args = dict(sync_method="interpolation", t_start=0.2, t_end=8.0, downsample=30, project_to_plane="xy")
    api = replay.score(tmp_path / "gt.tum", tmp_path / "est.tum", **args).leaderboard()
    res = CliRunner().invoke(main, ["score", str(tmp_path / "gt.tum"), str(tmp_path / "est.tum"),
                                    "--sync-method", "interpolation", "--t-start", "0.2", "--t-end", "8",
                                    "--downsample", "30", "--project-to-plane", "xy", "-o", str(tmp_path / "o.csv")])
    assert res.exit_code == 0, res.output
    cli = pd.read_csv(tmp_path / "o.csv", dtype={"config_hash": str})  # a hex hash like "1e64..." is not a float
    assert int(cli["matched"][0]) == int(api["matched"][0]) == 30
    assert cli["ape_trans_rmse"][0] == pytest.approx(api["ape_trans_rmse"][0], rel=1e-5)
    assert cli["config_hash"][0] == api["config_hash"][0]


@pytest.mark.parametrize("kw, words", [({"downsample": 1}, "downsample"), ({"project_to_plane": "xw"}, "project"),
                                       ({"sync_method": "linear"}, "sync_method"), ({"motion_filter": [1.0]}, "motion")])
def test_bad_options_are_one_line(kw, words):
    ref = _line(50, 0.1)
    with pytest.raises(replay.util.errors.ReplayError, match=words):
        replay.score(ref, ref, **kw)


def test_lengths_from_python_equal_the_cli(tmp_path):
    n = 300
    t = 0.1 * np.arange(n)
    a = t / 10.0
    q = np.c_[np.zeros(n), np.zeros(n), np.sin(a / 2), np.cos(a / 2)]
    ref = np.c_[t, 20 * np.sin(a), 20 * (1 - np.cos(a)), np.zeros(n), q]
    est = ref.copy()
    est[:, 1:3] += 0.05 * np.c_[np.sin(3 * a), np.cos(5 * a)]
    np.savetxt(tmp_path / "gt.tum", ref, fmt="%.9f")
    np.savetxt(tmp_path / "est.tum", est, fmt="%.9f")
    api = replay.score(tmp_path / "gt.tum", tmp_path / "est.tum", align="se3", lengths="10%,20%").lengths()
    res = CliRunner().invoke(main, ["score", str(tmp_path / "gt.tum"), str(tmp_path / "est.tum"), "-a",
                                    "--lengths", "10%,20%", "-o", str(tmp_path / "o.csv")])
    assert res.exit_code == 0, res.output
    cli = pd.read_csv(tmp_path / "o.csv")
    assert list(api["length"]) == list(cli["length"]) == ["10%", "20%"]
    for col in ("length_m", "rel_trans_rmse", "rel_trans_perc_mean", "rel_rot_deg_mean"):
        if col in cli:
            np.testing.assert_allclose(api[col].to_numpy(float), cli[col].to_numpy(float), rtol=1e-5)
    assert {"rel_trans_rmse", "length_m"} <= set(cli.columns)


def test_per_file_columns_score_a_csv_against_a_tum_reference(tmp_path):
    ref = _line(50, 0.1)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (50, 1))
    np.savetxt(tmp_path / "gt.tum", np.c_[ref.t, ref.p, q], fmt="%.9f")
    est = pd.DataFrame({"px": ref.p[:, 0] + 0.3, "time": ref.t, "py": ref.p[:, 1], "pz": ref.p[:, 2]})
    est.to_csv(tmp_path / "est.csv", index=False)
    gt, es = str(tmp_path / "gt.tum"), str(tmp_path / "est.csv")
    bad = CliRunner().invoke(main, ["score", gt, es, "--columns", "t=time,x=px,y=py,z=pz"])
    assert bad.exit_code == 2  # for every file: the TUM reference has no such header
    res = CliRunner().invoke(main, ["score", gt, es, "--columns", "est.csv=t=time,x=px,y=py,z=pz", "-o",
                                    str(tmp_path / "o.csv")])
    assert res.exit_code == 0, res.output
    assert pd.read_csv(tmp_path / "o.csv")["ape_trans_rmse"][0] == pytest.approx(0.3, rel=1e-6)


def test_evo_spellings(tmp_path):
    ref = _line(50, 0.1)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (50, 1))
    np.savetxt(tmp_path / "gt.tum", np.c_[ref.t, ref.p, q], fmt="%.9f")
    gt = str(tmp_path / "gt.tum")
    assert CliRunner().invoke(main, ["score", gt, gt, "-v"]).exit_code == 0
    res = CliRunner().invoke(main, ["score", gt, gt, "-p"])
    assert res.exit_code == 2 and "--plot FILE" in res.output and "Traceback" not in res.output
    res = CliRunner().invoke(main, ["score", gt, gt, "--save_plot", str(tmp_path / "f.png")])
    assert res.exit_code == 0 and (tmp_path / "f.png").stat().st_size > 1000


def test_tf_spellings():
    from replay.trajectory.bag import parse_tf
    from replay.util.errors import DataError

    for spec in ("map->base_link", "map,base_link", "map:base_link", "map.base_link", "/map->/base_link"):
        assert parse_tf(spec) == ("map", "base_link")
    with pytest.raises(DataError, match="redirection"):
        parse_tf("map-")
