"""Hostile per-filter noise settings (replay.filters.noise_params): each refused in one line,
before any run, naming the filter and the parameter (exit 2 from the CLI)."""
import json

import pytest
from click.testing import CliRunner

from replay.cli import main
from replay.filters import make_filter
from replay.filters.noise_params import check
from replay.run.pipeline import build_problem
from replay.util.errors import ReplayError

FORMATION = dict(dataset="sim/uav-formation", dataset_params={}, first=None, task="formation", task_params={},
                 filter="pf", filter_params={}, seed=0, alignment="se3", divergence_threshold=None, adapter=None)


@pytest.mark.parametrize("params, message", [
    ({"q_scale": 0}, "filter 'kf': q_scale must be a finite number > 0 (got 0)"),
    ({"p0_scale": -1.0}, "filter 'kf': p0_scale must be a finite number > 0 (got -1.0)"),
    ({"r_scale": float("inf")}, "filter 'kf': r_scale must be a finite number > 0 (got inf)"),
    ({"Q": [[1, 2], [2, 1]]}, "filter 'kf': Q must be a symmetric positive-definite matrix"),
    ({"Q": [[1, 0.5], [0.4, 1]]}, "filter 'kf': Q must be a symmetric positive-definite matrix"),
    ({"R": [1, 0, 2]}, "filter 'kf': R must be a symmetric positive-definite matrix"),
    ({"P0": -2}, "filter 'kf': P0 must be a symmetric positive-definite matrix"),
    ({"Q": "big"}, "filter 'kf': Q must be a symmetric positive-definite matrix"),
])
def test_bad_settings_refused_in_one_line(params, message):
    with pytest.raises(ReplayError) as err:
        make_filter("kf", **params)
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


@pytest.mark.parametrize("param, value, size", [("Q", [1.0, 1.0], "3x3 (this task's model has 3 state"),
                                                ("R", [[1, 0], [0, 2]], "3x3 (this task's model has 3 measurement"),
                                                ("P0", [1.0] * 4, "3x3 (this task's model has 3 state")])
def test_wrong_size_refused_before_any_run(tmp_path, param, value, size):
    """The size is known once the task is built: eval refuses it before any filter runs (exit 2)."""
    res = CliRunner().invoke(main, ["eval", "sim/auv-sonar", "--task", "position", "--dataset-param", "steps=20",
                                    "--filters", "ekf,kf", "-p", f"kf.{param}={json.dumps(value)}",
                                    "--out", str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    line = res.output.strip().splitlines()[-1]
    assert line.startswith(f"replay: error: filter 'kf': {param} must be {size}"), line
    assert not (tmp_path / "o").exists()


def test_a_model_that_draws_its_own_noise_without_refresh_is_refused():
    """A model that draws its own process noise and weighs by its own likelihood, without
    ``refresh_noise``: a change of Q or R would not reach them, so it is refused. Formation (paper
    003) defines ``refresh_noise`` and follows both (tests/test_hostile_p003.py)."""
    import numpy as np

    from replay.model import Model

    class Drawing(Model):
        nx, nz = 1, 1
        Q, R = np.eye(1), np.eye(1)

        def f(self, x, k):
            return x

        def h(self, x, k):
            return x

        def sample_f(self, x, k, rng):
            return x + rng.standard_normal(x.shape)

        def loglik(self, z, x, k, mask=None):
            return -0.5 * (z[0] - x[..., 0]) ** 2

    with pytest.raises(ReplayError, match=r"^filter 'pf': model Drawing computes its own sample_f from its "
                                          r"noise; Q and q_scale cannot change it"):
        check(make_filter("pf", q_scale=2.0), Drawing())
    with pytest.raises(ReplayError, match=r"^filter 'pf': model Drawing computes its own loglik"):
        check(make_filter("pf", r_scale=2.0), Drawing())
    check(make_filter("pf", p0_scale=2.0), Drawing())  # the prior is the filter's alone
    p = build_problem(FORMATION, 0)
    for params in ({"q_scale": 2.0}, {"r_scale": 2.0}):
        check(make_filter("pf", **params), p.model)




def _camp(tmp_path, grid):
    camp = tmp_path / "c.toml"
    camp.write_text('[campaign]\nname = "noise"\nruns = 2\n\n[[dataset]]\nid = "sim/auv-sonar"\n'
                    'tasks = ["position"]\nparams = { steps = 20 }\n\n[[filter]]\nname = "kf"\n'
                    f"grid = {grid}\n")
    return camp


def test_campaign_noise_of_the_wrong_size_stops_before_any_unit(tmp_path):
    camp = _camp(tmp_path, "{ Q = [2.0, [1, 1]] }")
    res = CliRunner().invoke(main, ["campaign", "run", str(camp), "-o", str(tmp_path / "o"), "-w", "1", "-q"])
    assert res.exit_code == 2, res.output
    assert res.output.strip().splitlines()[-1] == (
        f"replay: error: {camp}: sim/auv-sonar, task position: filter 'kf': Q must be 3x3 (this task's model has "
        "3 state components), or its diagonal (3 numbers), or a number; got size 2")
    assert not any((tmp_path / "o" / "units").rglob("*.json"))  # no unit computed


@pytest.mark.parametrize("grid, message", [
    ("{ q_scale = [1, 0] }", "q_scale: filter 'kf': q_scale must be a finite number > 0 (got 0)"),
    ("{ R = [[[1, 2], [2, 1]]] }", "R: filter 'kf': R must be a symmetric positive-definite matrix"),
    ("{ p0_scale = [true] }", "p0_scale: filter 'kf': p0_scale must be a finite number > 0 (got true)"),
])
def test_campaign_grid_of_bad_settings_refused_at_its_line(tmp_path, grid, message):
    camp = _camp(tmp_path, grid)
    res = CliRunner().invoke(main, ["campaign", "run", str(camp), "-o", str(tmp_path / "o"), "-w", "1", "-q"])
    assert res.exit_code == 2, res.output
    assert res.output.strip().splitlines()[-1].startswith(f"replay: error: {camp}:12: {message}")


@pytest.mark.parametrize("value", ["[[1,2,3],[4,5,6]]", "[1,NaN,2]", "[[1,0],[0,-1]]", "[]", "true", "0"])
def test_cli_matrix_values_refused(tmp_path, value):
    res = CliRunner().invoke(main, ["eval", "sim/auv-sonar", "--task", "position", "--dataset-param", "steps=20",
                                    "--filters", "kf", "-p", f"kf.R={value}", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    assert res.output.strip().splitlines()[-1].startswith("replay: error: filter 'kf': R must be a symmetric "
                                                         "positive-definite matrix"), res.output
