"""Hostile views: rates that would explode or empty the grid, bounds that are not numbers, views of a plain file."""
import numpy as np
import pytest
from click.testing import CliRunner

from replay.data import registry
from replay.cli import main
from replay.util.errors import ReplayError


@pytest.mark.parametrize("rate, message", [
    (1e6, "gives 89950001 grid point(s) over the 89.95 s of 1800 samples; more than 10 per sample"),
    (1e300, "more than 10 per sample would be nearly all masked"),
    (1e-6, "gives 1 grid point(s) over the 89.95 s of 1800 samples; 2 at least are needed"),
    (float("inf"), "rate must be a finite number > 0"),
    (float("nan"), "rate must be a finite number > 0"),
    (True, "rate must be a finite number > 0"),
])
def test_a_rate_is_refused_before_any_grid_is_allocated(rate, message):
    with pytest.raises(ReplayError, match=message.replace("(", r"\(").replace(")", r"\)")):
        registry.load_frame("sim/lake-depth", rng=0, rate=rate)


@pytest.mark.parametrize("window", ["1e400:", "nan:5", "5:inf", ":", "#-1:5", "3", "1:2:3", "#a:b", ""])
def test_a_window_that_is_not_two_bounds_is_refused(window):
    with pytest.raises(ReplayError, match="window"):
        registry.load_frame("sim/lake-depth", rng=0, window=window)


def test_a_window_of_one_sample_is_refused():
    with pytest.raises(ReplayError, match="the window #5:6 holds 1 sample"):
        registry.load_frame("sim/lake-depth", rng=0, window="#5:6")


def test_views_of_a_plain_file_through_the_cli(tmp_path):
    runner = CliRunner()
    log = tmp_path / "lake.csv"
    res = runner.invoke(main, ["datasets", "make", "sim/lake-depth", "--out", str(log), "--seed", "0"])
    assert res.exit_code == 0, res.output
    whole = registry.load_frame(str(log))
    cut = registry.load_frame(str(log), window="#100:500", rate=5)
    assert cut.meta["view"]["samples"] == [100, 500] and len(cut) == 101  # 19.95 s at 5 Hz: grid 0 .. 20 s
    np.testing.assert_array_equal(cut.channels["depth"].values[:3], whole.channels["depth"].values[100:112:4])
    assert len(registry.load_frame(str(log), window="#100:500", rate=5, first=30)) == 30  # first: after the view
    res = runner.invoke(main, ["datasets", "info", str(log), "--segment", "0.5:1", "--rate", "2"])
    assert res.exit_code == 0 and "view: {'rate': 2.0, 'segment': '0.5:1'" in res.output, res.output
    res = runner.invoke(main, ["eval", str(log), "--window", "500:600", "--filters", "ekf"])
    assert res.exit_code == 2 and "the window 500:600 holds no sample of the 89.95 s recording" in res.output


def test_a_campaign_refuses_a_view_before_any_unit(tmp_path):
    camp = tmp_path / "c.toml"
    camp.write_text('[campaign]\nname = "v"\nruns = 2\n\n[[dataset]]\nid = "sim/auv-sonar"\n'
                    'params = { steps = 30, window = "10:" }\n\n[[filter]]\nname = "ekf"\n')
    res = CliRunner().invoke(main, ["campaign", "run", str(camp), "-o", str(tmp_path / "out"), "-q"])
    assert res.exit_code == 2 and "sim/auv-sonar: window 10: starts 10 s after the first sample" in res.output
    assert not (tmp_path / "out" / "units").exists()
    camp.write_text(camp.read_text().replace('window = "10:"', "rate = 0"))
    res = CliRunner().invoke(main, ["campaign", "run", str(camp), "-o", str(tmp_path / "out"), "-q"])
    assert res.exit_code == 2 and "rate must be a finite number > 0" in res.output
