"""`replay report` on recorded estimates (``recorded:<name>``: NaN on every reference sample they were
not associated with): each track is drawn as a line through its associated samples, as many drawn
points as matched poses, in the reference's frame as scored; the reference too when no filter
gives it. Read from the figures' data."""
import gzip
import json
from pathlib import Path

import numpy as np
import pytest

from replay.outputs import plots
from replay.outputs.report import build

N = 200  # reference samples (0.1 s)


def _write(d, name, t, pos, err):
    head = "run,k,t,x0,x1,x2,P00,P11,P22,err_x,err_y,err_z"
    rows = ([0, k, t[k], *pos[k], *([np.nan] * 3), *err[k]] for k in range(len(t)))
    lines = [head] + [",".join(repr(float(v)) for v in row) for row in rows]
    with gzip.open(d / "estimates" / f"{name}.csv.gz", "wt") as fh:
        fh.write("\n".join(lines) + "\n")


def _eval_dir(d, with_filter=False):
    """Two recorded estimates associated on every 5th / 7th sample (a 10 s gap in the second), aligned
    as scored (position = reference + error), optionally a filter estimated on every sample."""
    (d / "estimates").mkdir(parents=True)
    t = np.arange(N) * 0.1
    truth = np.column_stack([np.cos(t / 3) * 10, np.sin(t / 3) * 10, t * 0.1])
    rng = np.random.default_rng(1)
    counts = {}
    for name, step, cut in (("recorded:orb", 5, None), ("recorded:sptam", 7, slice(80, 180))):
        err = np.full_like(truth, np.nan)
        k = np.arange(0, N, step)
        if cut is not None:
            k = k[(k < cut.start) | (k >= cut.stop)]
        err[k] = rng.normal(0, 0.3, (len(k), 3))
        _write(d, name, t, truth + err, err)
        counts[name] = len(k)
    labels = list(counts)
    if with_filter:
        err = rng.normal(0, 0.2, truth.shape)
        err[50:60] = np.nan  # the reference masked there
        _write(d, "ekf", t, truth + np.nan_to_num(err), err)
        labels.append("ekf")
    (d / "leaderboard.csv").write_text("dataset,task,filter,label,runs,pos_rmse\n"
                                       + "".join(f"bag,position,{f},{f},1,0.3\n" for f in labels))
    (d / "manifest.json").write_text(json.dumps({"config": {"dataset": "bag", "task": "position"}}))
    return truth, counts


def _lines(fig, gid):
    return [ln for ax in fig.axes for ln in ax.lines if ln.get_gid() == gid]


def _points(line):
    xy = np.asarray(line.get_xydata(), float)
    return xy[np.isfinite(xy).all(axis=1)]


def test_recorded_tracks_drawn_through_their_associated_samples(tmp_path):
    truth, counts = _eval_dir(tmp_path / "ev")
    secs, pal, figs = build(tmp_path / "ev")
    assert secs[0].sparse == set(counts)
    traj = next(f for _, n, f in figs if n == "trajectory")
    plane = traj.axes[0]
    for name, n in counts.items():
        (line,) = [ln for ln in plane.lines if ln.get_gid() == name]
        pts = _points(line)
        assert len(pts) == n  # every matched pose drawn, none invented
        x = np.asarray(line.get_xdata(), float)
        runs = np.diff(np.r_[0, np.isfinite(x).astype(int), 0])
        assert (np.flatnonzero(runs == -1) - np.flatnonzero(runs == 1)).min() > 1  # segments, never lone dots
    x = np.asarray([ln for ln in plane.lines if ln.get_gid() == "recorded:sptam"][0].get_xdata(), float)
    assert np.isnan(x).sum() == 1  # the 10 s without an associated pose is a gap, nothing else is
    (ref,) = [ln for ln in plane.lines if ln.get_gid() == "reference"]
    union = len(set(range(0, N, 5)) | {k for k in range(0, N, 7) if not 80 <= k < 180})
    assert len(_points(ref)) == union
    # the reference drawn is the one scored: its points lie on the truth
    assert np.allclose(_points(ref), truth[sorted(set(range(0, N, 5)) | {k for k in range(0, N, 7)
                                                                           if not 80 <= k < 180}), :2])
    assert not any(p.get_gid() == "masked" for ax in traj.axes for p in ax.patches)  # unknown, not "masked"
    err = next(f for _, n, f in figs if n == "error")
    for name, n in counts.items():
        assert sum(len(_points(ln)) for ln in _lines(err, name)) == n
        assert not any(p.get_gid() == "masked" for ax in err.axes for p in ax.patches)


def test_with_a_filter_the_reference_keeps_its_masked_gaps(tmp_path):
    truth, counts = _eval_dir(tmp_path / "ev", with_filter=True)
    secs, pal, figs = build(tmp_path / "ev")
    traj = next(f for _, n, f in figs if n == "trajectory")
    (ref,) = [ln for ln in traj.axes[0].lines if ln.get_gid() == "reference"]
    x = np.asarray(ref.get_xdata(), float)
    assert len(x) == N and np.isnan(x[50:60]).all() and np.isfinite(x).sum() == N - 10
    assert any(p.get_gid() == "masked" for ax in traj.axes for p in ax.patches)
    for name, n in counts.items():
        assert len(_points(next(iter(_lines(traj, name))))) == n


def test_joined_keeps_finite_samples_and_breaks_time_gaps():
    t, y = plots.joined([0, 1, 2, 3, 4, 20, 21], [1, np.nan, 3, np.nan, 5, 6, 7])
    assert list(t[:3]) == [0, 2, 4] and np.isnan(t[3]) and list(y[4:]) == [6, 7]


def test_a_track_without_motion_in_the_plane_is_a_marker_not_a_blank_panel(tmp_path):
    """An AR.Drone's raw odometry (robot_localization's test3 bag) holds x = y = 0 throughout: a line of
    no length draws nothing, so the x-y panel was blank; it is a marker and the title says so."""
    d = tmp_path / "ev"
    (d / "estimates").mkdir(parents=True)
    t = np.arange(50) * 0.1
    pos = np.column_stack([np.zeros(50), np.zeros(50), np.sin(t)])
    _write(d, "recorded:odom", t, pos, np.zeros_like(pos))
    (d / "leaderboard.csv").write_text("dataset,task,filter,label,runs,pos_rmse\nbag,position,recorded:odom,"
                                       "recorded:odom,1,0\n")
    (d / "manifest.json").write_text(json.dumps({"config": {"dataset": "bag", "task": "position"}}))
    _, _, figs = build(d)
    plane = next(f for _, n, f in figs if n == "trajectory").axes[0]
    assert plane.get_title().endswith("(no motion in it)")
    for ln in plane.lines:
        assert ln.get_marker() == "o" and ln.get_markevery() == [0] and len(_points(ln)) == 50
    z = next(f for _, n, f in figs if n == "trajectory").axes[1]
    assert all(ln.get_marker() in ("None", None, "") for ln in z.lines)  # moving in time: plain lines


def test_campaign_recorded_estimate_keeps_the_stored_reference_and_its_masks():
    """A campaign stores the reference itself (NaN only where masked): with a recorded estimate alone,
    the reference is drawn whole, breaking at the masked samples, and they are shaded as masked."""
    from replay.outputs.palette import Palette
    from replay.outputs.report_data import Section
    from replay.outputs.report_plots import section_figures

    t = np.arange(N) * 0.1
    truth = np.column_stack([np.cos(t), np.sin(t), t])
    ref = truth.copy()
    ref[100:110] = np.nan
    pos = np.full_like(truth, np.nan)
    pos[::4] = truth[::4] + 0.1
    pos[100:110] = np.nan
    err = pos - truth
    sec = Section("bag", "position", ("x", "y", "z"), sparse={"recorded:orb"})
    sec.runs["recorded:orb"] = {0: {"t": t, "pos": pos, "ref": ref, "err": err,
                                    "valid": np.isfinite(ref).all(axis=1) & np.isfinite(err).all(axis=1)}}
    sec.metrics["recorded:orb"] = {0: {"pos_rmse": 0.17}}
    sec.rows = [{"label": "recorded:orb", "pos_rmse": 0.17, "runs": 1}]
    figs = dict(section_figures(sec, Palette(["recorded:orb"])))
    plane = figs["trajectory"].axes[0]
    (r,) = [ln for ln in plane.lines if ln.get_gid() == "reference"]
    x = np.asarray(r.get_xdata(), float)
    assert len(x) == N and np.isnan(x[100:110]).all() and np.isfinite(x).sum() == N - 10
    (e,) = [ln for ln in plane.lines if ln.get_gid() == "recorded:orb"]
    assert len(_points(e)) == len(range(0, N, 4)) - len(range(100, 110, 4))
    assert any(p.get_gid() == "masked" for ax in figs["trajectory"].axes for p in ax.patches)


def test_isolated_samples_are_drawn_as_a_line():
    from replay.util.series import isolated, line

    f = np.zeros(100, bool)
    f[::5] = True
    assert isolated(f) and not isolated(np.ones(100, bool)) and not isolated(f[:1])
    masked = np.ones(100, bool)
    masked[40:50] = False
    assert not isolated(masked)
    t = np.arange(100.0)
    y = np.where(f, t, np.nan)
    tt, yy = line(t, y)
    assert np.array_equal(tt, t[::5]) and np.array_equal(yy, t[::5])  # through the 20 samples, no NaN
    y = np.where(masked, t, np.nan)
    tt, yy = line(t, y)
    assert len(tt) == 100 and np.isnan(yy[40:50]).all()  # a masked stretch still breaks the line


def test_reference_held_at_fixes_only_is_a_line_with_its_errors(tmp_path):
    """gps-odom: the reference is known at the held-out fixes only (every 10th step of the time axis),
    a filter's estimate on every step, its errors at the fixes: the reference and the error curves are
    lines through the fixes (not dots), and nothing is shaded as masked."""
    from replay.outputs.palette import Palette
    from replay.outputs.report_data import Section
    from replay.outputs.report_plots import section_figures

    t = np.arange(N) * 0.1
    truth = np.column_stack([np.cos(t), np.sin(t)])
    ref = np.full_like(truth, np.nan)
    ref[::10] = truth[::10]
    sec = Section("bag", "gps-odom", ("east", "north"))
    rng = np.random.default_rng(3)
    for lab in ("ekf", "ukf"):
        sec.runs[lab], sec.metrics[lab] = {}, {}
        for r in range(3):
            pos = truth + rng.normal(0, 0.1, truth.shape)
            err = pos - ref
            sec.runs[lab][r] = {"t": t, "pos": pos, "ref": ref, "err": err, "valid": np.isfinite(err).all(axis=1)}
            sec.metrics[lab][r] = {"pos_rmse": 0.1}
        sec.rows.append({"label": lab, "pos_rmse": 0.1, "runs": 3})
    figs = dict(section_figures(sec, Palette(["ekf", "ukf"])))
    (r,) = [ln for ln in figs["trajectory"].axes[0].lines if ln.get_gid() == "reference"]
    assert len(r.get_xdata()) == len(_points(r)) == N // 10  # one line through the 20 fixes
    for lab in ("ekf", "ukf"):
        (e,) = [ln for ln in figs["trajectory"].axes[0].lines if ln.get_gid() == lab]
        assert len(_points(e)) == N  # the estimate on every step
        centre = [ln for ln in figs["error"].axes[("ekf", "ukf").index(lab)].lines
                  if ln.get_gid() == lab and ln.get_label() == lab]
        assert len(centre[0].get_xdata()) == len(_points(centre[0])) == N // 10
    assert not any(p.get_gid() == "masked" for f in figs.values() for ax in f.axes for p in ax.patches)


@pytest.mark.slow  # loads 60 s of a real bag (about 5 s)
def test_python_plots_draw_recorded_estimates_as_lines(shared_dir):
    import replay

    mcap = shared_dir / "datasets" / "bags" / "derived" / "rl_test1_60s_mcap"
    mapping = Path(__file__).resolve().parents[1] / "docs" / "mappings" / "rl_test1_recorded.toml"
    ev = replay.evaluate(str(mcap), filters=["recorded:wheel_odom"], dataset_params={"mapping": str(mapping)})
    matched = int(ev.rows[0]["scored"])
    assert matched == 56  # of 120 held-out fixes (replay eval's note)
    lines = {ln.get_label(): ln for ln in replay.plot_track(ev).axes[0].lines}
    assert len(_points(lines["reference"])) == 120 and len(_points(lines["recorded:wheel_odom"])) == matched
    for name, n in (("reference", 120), ("recorded:wheel_odom", matched)):  # lines: few NaN (time gaps), not
        assert len(lines[name].get_xdata()) <= n + 5, name  # one NaN per sample of the IMU-rate time axis
    (err,) = replay.plot_errors(ev).axes[0].lines
    assert len(_points(err)) == matched and len(err.get_xdata()) <= matched + 5  # a line, not NaN-separated dots
