"""`replay report` of a recording with recorded estimates (evo's ROS_example.bag: ORB-SLAM and S-PTAM
against its ground truth, both aligned by SE(3) as the mapping docs/mappings/evo_ros_example.toml
says) in headless Chromium, and read back from the figures' data: the x-y panel is not blank, each
recorded track is drawn with as many points as matched poses (evo's counts, 2550 and 1667), aligned
as scored (the RMSE of the drawn track against the drawn reference is the ATE, 5.5099 m, not the
8.508 m before the fit), and the page shows the tracks in their colours."""
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_report_browser import HEIGHT, WIDTH, _need_chromium, page_requests, render

from replay.cli import main
from replay.outputs.report import build

MAPPING = Path(__file__).resolve().parents[1] / "docs" / "mappings" / "evo_ros_example.toml"
MATCHED = {"recorded:ORB-SLAM": 2550, "recorded:S-PTAM": 1667}  # replay score ... -a (= evo_ape's counts)


def _finite(line):
    xy = np.asarray(line.get_xydata(), float)
    return xy[np.isfinite(xy).all(axis=1)]


@pytest.mark.slow  # loads an 889 s bag (about 10 s) and starts Chromium
def test_report_of_recorded_estimates_draws_aligned_tracks_in_chromium(shared_dir, tmp_path):
    _need_chromium()
    bag = shared_dir / "datasets" / "bags" / "evo" / "ROS_example.bag"
    out = tmp_path / "ev"
    res = CliRunner().invoke(main, ["eval", str(bag), "--mapping", str(MAPPING), "--filters", "none", "-o", str(out)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["report", str(out)])
    assert res.exit_code == 0, res.output

    secs, pal, figs = build(out)
    (sec,) = secs
    rows = {r["label"]: r for r in sec.rows}
    traj = next(f for _, n, f in figs if n == "trajectory")
    plane, zt = traj.axes[0], traj.axes[1]
    assert plane.get_title().startswith("x-y plane")
    lines = {ln.get_gid(): ln for ln in plane.lines}
    ztl = {ln.get_gid(): ln for ln in zt.lines}
    ref_xy, ref_tz = _finite(lines["reference"]), _finite(ztl["reference"])
    assert len(ref_xy) == len(ref_tz) >= max(MATCHED.values())
    for name, n in MATCHED.items():
        xy, tz = _finite(lines[name]), _finite(ztl[name])
        assert len(xy) == len(tz) == n == int(float(rows[name]["scored"]))  # every matched pose drawn
        assert np.ptp(xy[:, 0]) > 40 and np.ptp(xy[:, 1]) > 10  # a track, not a blank panel or a few dots
        at = np.searchsorted(ref_tz[:, 0], tz[:, 0])
        assert np.array_equal(ref_tz[at, 0], tz[:, 0])  # the reference drawn at every matched pose
        d = np.column_stack([xy - ref_xy[at], tz[:, 1] - ref_tz[at, 1]])
        rmse = float(np.sqrt(np.mean(np.sum(d ** 2, axis=1))))
        assert rmse == pytest.approx(float(rows[name]["ate"]), rel=1e-9)  # drawn as scored: aligned
        assert rmse < float(rows[name]["pos_rmse_unaligned"]) - 2
    assert rmse == pytest.approx(6.316710, abs=1e-6)  # S-PTAM: evo_ape ... -a

    page = out / "report" / "report.html"
    img, reqs = render(page, tmp_path)
    assert img.shape[:2] == (HEIGHT, WIDTH) and page_requests(reqs) == []
    rows_used = np.flatnonzero((img < 245).any(axis=2).any(axis=1))
    content = img[:rows_used.max() + 1]
    assert 0.04 < 1 - (content > 245).all(axis=2).mean() and content.std() > 20  # not blank (measured: 0.059)
    for name in MATCHED:  # each track rendered in its colour (antialiased 1-px lines; measured: 2554, 2017)
        c = pal.colour(name)
        rgb = np.array([int(c[k:k + 2], 16) for k in (1, 3, 5)])
        assert (np.abs(img.astype(int) - rgb).max(axis=2) <= 24).sum() > 1200, name
