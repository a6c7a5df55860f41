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
