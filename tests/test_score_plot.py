"""``replay score --plot`` / ``ScoreResult.plot()``: plot modes pick the coordinates, the error map's
colours are the APE values, RPE over time, evo_traj's xyz / rpy panels, units on every axis, the
files written. Read from the figures' data."""
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

import replay
from replay.cli import main
from replay.trajectory import make
from replay.trajectory.files import write_tum
from replay.trajectory.plot_series import euler_deg
from replay.util.errors import ReplayError

N = 120


def _pair(seed=0):
    rng = np.random.default_rng(seed)
    s = np.arange(N) * 0.1
    p = np.column_stack([6 * np.cos(s / 3), 4 * np.sin(s / 3), 0.5 * s])
    q = Rotation.from_euler("xyz", np.column_stack([0.2 * np.sin(s), 0.1 * np.cos(s), s / 3])).as_quat()
    R = Rotation.from_euler("z", 0.7).as_matrix()
    pe = (p + rng.normal(0, 0.05, p.shape)) @ R.T + [3, -1, 2]
    qe = (Rotation.from_matrix(R) * Rotation.from_quat(q) * Rotation.from_rotvec(rng.normal(0, 0.02, (N, 3))))
    return make(100 + s, p, q, source="gt", name="gt"), make(100 + s, pe, qe.as_quat(), source="est", name="est")


@pytest.fixture(scope="module")
def result():
    ref, est = _pair()
    return replay.score(ref, [est], align="se3", rpe=True, pose_relation=["trans", "angle_deg"])


def _units_everywhere(fig):
    for ax in fig.axes:
        labels = [ax.get_xlabel(), ax.get_ylabel()] + ([ax.get_zlabel()] if hasattr(ax, "get_zlabel") else [])
        for text in labels:
            if text:
                assert text.endswith(")") and "(" in text, text


@pytest.mark.parametrize("mode,cols", [("xy", (0, 1)), ("xz", (0, 2)), ("yz", (1, 2)), ("zy", (2, 1))])
def test_plot_modes_pick_the_coordinates(result, mode, cols):
    fig = result.plot(mode=mode)
    ax = fig.axes[0]
    (est,) = [ln for ln in ax.lines if ln.get_gid() == "est"]
    (ref,) = [ln for ln in ax.lines if ln.get_gid() == "reference"]
    assert np.array_equal(est.get_xydata(), result["est"].aligned.p[:, cols])
    assert np.array_equal(ref.get_xydata(), result.reference.p[:, cols])  # whole, one continuous line
    assert ax.get_xlabel() == f"{'xyz'[cols[0]]} (m)" and ax.get_ylabel() == f"{'xyz'[cols[1]]} (m)"
    _units_everywhere(fig)


def test_plot_mode_xyz_is_3d(result):
    fig = result.plot(mode="xyz", kind="map")
    ax = fig.axes[0]
    assert ax.name == "3d" and ax.get_zlabel() == "z (m)"
    (ref,) = [ln for ln in ax.lines if ln.get_gid() == "reference"]
    assert np.allclose(np.column_stack(ref.get_data_3d()), result.reference.p)
    with pytest.raises(ReplayError, match=r"^plot mode 'xw': expected one of xy, xz, yz, yx, zx, zy, xyz$"):
        result.plot(mode="xw")
    with pytest.raises(ReplayError, match=r"^plot: kind 'raw': expected one of trajectories, map, xyz, rpy, all$"):
        result.plot(kind="raw")


def test_error_map_colours_are_the_ape(result):
    s = result["est"]
    for rel in ("trans", "angle_deg"):
        fig = result.plot(kind="map", relation=rel)
        (lc,) = [c for c in fig.axes[0].collections if c.get_gid() == "est"]
        assert np.array_equal(lc.get_array(), s.ape[rel][1:])  # segment k..k+1: the APE at pose k+1
        assert np.array_equal(lc.get_segments()[5], s.aligned.p[5:7, :2])
        assert lc.get_clim() == (s.ape[rel].min(), s.ape[rel].max())
        bar = fig.axes[-1]
        assert bar.get_ylabel() == {"trans": "APE translation (m)", "angle_deg": "APE rotation angle (deg)"}[rel]


def test_ape_rmse_and_rpe_over_time(result):
    s = result["est"]
    fig = result.plot()
    err_ax, rpe_ax = fig.axes[1], fig.axes[2]
    (ape,) = [ln for ln in err_ax.lines if ln.get_gid() == "est"]
    assert np.array_equal(ape.get_ydata(), s.ape["trans"])
    assert np.allclose(ape.get_xdata(), s.reference.t - s.reference.t[0])
    (rmse,) = [ln for ln in err_ax.lines if ln.get_gid() == "est rmse"]
    assert rmse.get_ydata()[0] == pytest.approx(result.stats().query("metric == 'ape' and relation == 'trans'")
                                                ["rmse"].item(), rel=1e-12)
    (rpe,) = [ln for ln in rpe_ax.lines if ln.get_gid() == "est"]
    i, j = s.rpe_pairs
    assert np.array_equal(rpe.get_ydata(), s.rpe["trans"]) and np.allclose(rpe.get_xdata(), s.reference.t[j] - 100)
    assert "(m)" in rpe_ax.get_ylabel()


def test_xyz_and_rpy_panels(result):
    s = result["est"]
    figs = result.plot(kind="all")
    assert list(figs) == ["trajectories", "map", "xyz", "rpy"]
    for k, ax in enumerate(figs["xyz"].axes):
        (ln,) = [ln for ln in ax.lines if ln.get_gid() == "est"]
        assert np.array_equal(ln.get_ydata(), s.aligned.p[:, k]) and ax.get_ylabel() == f"{'xyz'[k]} (m)"
    expect = Rotation.from_quat(s.aligned.q).as_euler("xyz", degrees=True)  # extrinsic x-y-z = evo's sxyz
    assert np.allclose(euler_deg(s.aligned.q), expect, atol=1e-9)
    for k, ax in enumerate(figs["rpy"].axes):
        (ln,) = [ln for ln in ax.lines if ln.get_gid() == "est"]
        assert np.allclose(ln.get_ydata(), expect[:, k], atol=1e-9)
        assert ax.get_ylabel() == f"{('roll', 'pitch', 'yaw')[k]} (deg)"
    for fig in figs.values():
        _units_everywhere(fig)


def test_no_rpy_without_orientations():
    ref, est = _pair(1)
    est = make(est.t, est.p, source="est", name="est")
    r = replay.score(ref, [est], align="se3")
    assert list(r.plot(kind="all")) == ["trajectories", "map", "xyz"]
    with pytest.raises(ReplayError, match=r"^plot: no rpy figure: the reference or the estimates have no orient"):
        r.plot(kind="rpy")


@pytest.mark.slow  # writes four PNGs: about 3 s
def test_cli_writes_every_figure_in_the_mode(tmp_path):
    ref, est = _pair(2)
    write_tum(tmp_path / "gt.tum", ref)
    write_tum(tmp_path / "est.tum", est)
    png = tmp_path / "figs" / "p.png"
    res = CliRunner().invoke(main, ["score", str(tmp_path / "gt.tum"), str(tmp_path / "est.tum"), "-a", "--rpe",
                                    "--plot", str(png), "--plot_mode", "xz"])
    assert res.exit_code == 0, res.output
    names = ["p.png", "p_map.png", "p_xyz.png", "p_rpy.png"]
    assert sorted(p.name for p in png.parent.iterdir()) == sorted(names)
    assert f"plot: {', '.join(str(png.parent / n) for n in names)}" in res.output
    assert all((png.parent / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for n in names)
    res = CliRunner().invoke(main, ["score", str(tmp_path / "gt.tum"), str(tmp_path / "est.tum"), "-a", "--rpe",
                                    "-r", "point_distance_error_ratio", "--plot", str(png)])  # an RPE-only relation
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in png.parent.iterdir()) == ["p.png", "p_rpy.png", "p_xyz.png"]  # no stale map
    assert f"(removed the earlier {png.parent / 'p_map.png'})" in res.output
    res = CliRunner().invoke(main, ["score", str(tmp_path / "gt.tum"), str(tmp_path / "est.tum"), "--plot-mode", "xw"])
    assert res.exit_code == 2 and "Traceback" not in res.output
