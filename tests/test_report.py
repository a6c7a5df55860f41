"""`replay report` on a campaign directory and on a `replay eval` directory."""
import base64
import re

import pytest
from click.testing import CliRunner

from replay.cli import main

CAMPAIGN = """\
[campaign]
runs = 4
batch = 4

[[dataset]]
id = "sim/auv-sonar"
params = { steps = 25 }

[[filter]]
name = "ukf"

[[filter]]
name = "ekf"
"""


def _pngs_in(html):
    imgs = re.findall(r'src="data:image/png;base64,([^"]+)"', html)
    return [base64.b64decode(b) for b in imgs]


@pytest.mark.slow
def test_report_on_campaign_and_eval_dirs(tmp_path):
    (tmp_path / "c.toml").write_text(CAMPAIGN)
    out = tmp_path / "camp"
    res = CliRunner().invoke(main, ["campaign", "run", str(tmp_path / "c.toml"), "-o", str(out), "-w", "1", "-q"])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["report", str(out)])
    assert res.exit_code == 0, res.output
    page = (out / "report" / "report.html").read_text()
    imgs = _pngs_in(page)
    assert len(imgs) == 4 and all(i.startswith(b"\x89PNG") for i in imgs)  # trajectory, error, RMSE, NEES/NIS
    assert "<td>ukf</td>" in page and "Paired comparisons" in page
    assert {p.name for p in (out / "report").glob("*.png")} == {
        "trajectory_0.png", "error_0.png", "rmse_0.png", "consistency_0.png"}

    ev = tmp_path / "ev"
    res = CliRunner().invoke(main, ["eval", "sim/auv-sonar", "-f", "ekf,ckf", "--runs", "2", "-o", str(ev)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["report", str(ev), "-o", str(tmp_path / "r")])
    assert res.exit_code == 0, res.output
    page = (tmp_path / "r" / "report.html").read_text()
    assert len(_pngs_in(page)) == 3 and "<td>ckf</td>" in page  # no NEES: eval stores only diag(P)


def test_report_on_other_dir_is_one_line_error(tmp_path):
    res = CliRunner().invoke(main, ["report", str(tmp_path)])
    assert res.exit_code == 2 and "not a result directory" in res.output


def test_report_table_shows_lost_and_collapsed():
    from replay.outputs.report import TABLE, _table

    rows = [{"dataset": "d", "task": "t", "label": "pf", "runs": 20, "diverged": 0, "lost": 2, "lost_share": 0.7,
             "pos_rmse": 14.75, "pos_rmse_median": 3.44, "anees": float("nan"), "anees_flag": "collapsed"},
            {"dataset": "d", "task": "t", "label": "ekf", "runs": 20, "diverged": 0, "lost": 0, "lost_share": 0.0,
             "pos_rmse": 2.40, "pos_rmse_median": 2.39, "anees": 10.04, "anees_flag": "optimistic"}]
    page = _table(rows, TABLE)
    assert "<th>lost</th>" in page and "<td>2/20*</td>" in page and "<td>0/20</td>" in page
    assert "<td>collapsed</td>" in page and "<td>10.04</td>" in page and "<td>3.44</td>" in page
