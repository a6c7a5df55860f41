"""Parameters declared once (replay.util.params) and refused strictly everywhere: the CLI, campaign files,
tasks, simulators; one line naming the parameter, what it accepts and the value; exit status 2."""
from __future__ import annotations

import inspect
import math
import subprocess
import sys

import numpy as np
import pytest

from replay.data import registry
from replay.models.noise import Covariance, as_matrix
from replay.sim import Intervals, Numbers
from replay.tasks import TASKS, make_task, task_class
from replay.util.errors import ReplayError
from replay.util.params import Param, validate


# ---------------------------------------------------------------- Param


def refused(param, value) -> str:
    with pytest.raises(ReplayError) as err:
        param.check(value, "filter 'x'")
    return str(err.value)


def test_int_refuses_fractions_bools_and_strings():
    p = Param("n_particles", int, 1000, "particles", low=1)
    assert p.check(5) == 5
    assert refused(p, 1.5) == "filter 'x': n_particles must be an integer >= 1 (got 1.5)"
    assert refused(p, True) == "filter 'x': n_particles must be an integer >= 1 (got true)"
    assert refused(p, "3") == "filter 'x': n_particles must be an integer >= 1 (got '3')"
    assert refused(p, 0) == "filter 'x': n_particles must be an integer >= 1 (got 0)"


def test_int_takes_numpy_integers_but_not_numpy_floats_or_bools():
    import numpy as np

    p = Param("n_particles", int, 1000, "particles", low=1)
    for v in np.arange(1, 4):  # a sweep built with numpy
        assert p.check(v) == int(v) and type(p.check(v)) is int
    assert refused(p, np.float64(7.0)) == "filter 'x': n_particles must be an integer >= 1 (got 7.0)"
    assert "got true" in refused(p, np.bool_(True)) or "got True" in refused(p, np.bool_(True))


def test_float_refuses_nan_inf_and_bools_and_takes_integers():
    p = Param("r", float, 1.0, "variance", low=0, low_open=True)
    assert p.check(2) == 2.0 and isinstance(p.check(2), float)
    for value, shown in ((math.nan, "nan"), (math.inf, "inf"), (-math.inf, "-inf"), (False, "false"),
                         (0.0, "0.0"), (-2, "-2")):
        assert refused(p, value) == f"filter 'x': r must be a finite number > 0 (got {shown})"
    assert Param("x", float, 0.0, "", finite=False).check(math.inf) == math.inf
    assert "(got nan)" in refused(Param("x", float, 0.0, "", finite=False), math.nan)


def test_bounds_open_and_closed():
    p = Param("eps", float, 0.5, "", low=0, high=1, high_open=True)
    assert p.check(0) == 0.0 and p.check(0.999) == 0.999
    assert refused(p, 1.0) == "filter 'x': eps must be a finite number in [0, 1) (got 1.0)"
    assert "<= 3" in refused(Param("k", int, 1, "", high=3), 4)


def test_bool_str_list_and_optional():
    b = Param("compiled", bool, True, "")
    assert b.check(False) is False
    assert refused(b, 1) == "filter 'x': compiled must be true or false (got 1)"
    s = Param("resampling", str, "systematic", "", choices=("systematic", "multinomial"))
    assert s.check("multinomial") == "multinomial"
    assert refused(s, "stratified") == ("filter 'x': resampling must be one of systematic, multinomial "
                                        "(got 'stratified')")
    d = Param("dims", str, "auto", "", choices=("auto", "2", "3"))  # --task-param dims=2 parses as a number
    assert d.check(2) == "2" and d.check("3") == "3"
    assert refused(d, 4) == "filter 'x': dims must be one of auto, 2, 3 (got 4)" and refused(d, True).endswith("(got true)")
    assert refused(s, 2).endswith("(got 2)")
    v = Param("x0", list, (0.0, 0.0), "", length=2)
    assert v.check([1, 2]) == (1.0, 2.0)
    assert refused(v, [1, 2, 3]) == "filter 'x': x0 must be a list of numbers of length 2 (got [1, 2, 3])"
    assert "(got [1, nan])" in refused(v, [1, math.nan])
    o = Param("z0", float, None, "", optional=True)
    assert o.check(None) is None and o.check(3) == 3.0
    assert refused(o, "up") == "filter 'x': z0 must be a finite number (or null) (got 'up')"


def test_validate_fills_defaults_and_refuses_unknown_names():
    params = (Param("a", int, 1, ""), Param("b", float, 2.0, ""))
    assert validate(params, {"b": 3}, "task 't'") == {"a": 1, "b": 3.0}
    with pytest.raises(ReplayError, match=r"^task 't': unknown parameter 'c' \(known: a, b\)$"):
        validate(params, {"c": 1}, "task 't'")


def test_covariance_numbers_and_intervals():
    c = Covariance("R", list, (1.0, 2.0), "", dim=2)
    assert c.check([[4, 0], [0, 9]]) == (4.0, 9.0)  # a diagonal matrix is stored as its diagonal
    assert c.check(np.array([[2.0, 0.5], [0.5, 1.0]])) == ((2.0, 0.5), (0.5, 1.0))
    assert np.array_equal(as_matrix((4.0, 9.0)), np.diag([4.0, 9.0]))
    accepts = "a 2x2 symmetric positive-definite matrix or its diagonal (2 positive numbers)"
    for bad, shown in (([1, -1], "[1, -1]"), ([[1, 2], [2, 1]], "[[1, 2], [2, 1]]"), ([[1, 0], [1, 1]],
                       "[[1, 0], [1, 1]]"), ([1, 2, 3], "[1, 2, 3]"), (math.inf, "inf"), ([1, math.nan], "[1, nan]"),
                       ([True, 1], "[True, 1]")):
        assert refused(c, bad) == f"filter 'x': R must be {accepts} (got {shown})"
    n = Numbers("base_sigma", list, (1.0,), "", length=3, low=0)
    assert n.check([0, 1, 2]) == (0.0, 1.0, 2.0)
    assert refused(n, [1, -1, 1]) == ("filter 'x': base_sigma must be a list of 3 finite numbers, each >= 0 "
                                      "(got [1, -1, 1])")
    assert "list of one or more" in refused(Numbers("r", list, (1.0,), ""), [])
    i = Intervals("gaps", list, (), "")
    assert i.check([[1, 2], [5, 6.5]]) == ((1.0, 2.0), (5.0, 6.5)) and i.check([]) == ()
    assert refused(i, [[2, 1]]).endswith("start < end (got [[2, 1]])")


# ---------------------------------------------------------------- the declarations themselves


def _sims():
    return [ds for ds in registry.all_datasets().values() if ds.kind == "sim"]


def test_every_default_passes_its_own_declaration():
    owners = [(f"task {n}", task_class(n).PARAMS) for n in TASKS]
    owners += [(ds.id, registry.generator(ds).PARAMS) for ds in _sims()]
    for owner, params in owners:
        assert params, owner
        assert len({p.name for p in params}) == len(params), owner
        for p in params:
            assert p.doc, (owner, p.name)
            if p.default is not None or not p.optional:
                assert p.check(p.default) == p.default, (owner, p.name)


def test_generators_take_exactly_their_declared_parameters():
    for ds in _sims():
        make = registry.generator(ds)
        names = [p.name for p in make.PARAMS]
        kw = [q.name for q in inspect.signature(inspect.unwrap(make)).parameters.values()
              if q.kind == q.KEYWORD_ONLY]
        assert kw in ([], names), ds.id  # auv-bag passes **params on to make_bag


def test_tasks_canonical_params_round_trip():
    for name in TASKS:
        p = make_task(name).params()
        assert make_task(name, **p).params() == p  # what `replay rerun` and campaigns do
    assert make_task("sonar", R=[[2, 0, 0], [0, 1e-4, 0], [0, 0, 1e-4]]).params() == make_task("sonar").params()


def test_task_and_sim_refusals_name_owner_parameter_and_value():
    cases = [
        (lambda: make_task("ungm", r=-2), "task 'ungm': r must be a finite number > 0 (or null) (got -2)"),
        (lambda: make_task("gps-odom", gps_every=2.5), "task 'gps-odom': gps_every must be an integer >= 1 (got 2.5)"),
        (lambda: make_task("dead-reckoning", score="best"),
         "task 'dead-reckoning': score must be one of navigation, fixes (got 'best')"),
        (lambda: make_task("position", nope=1), "task 'position': unknown parameter 'nope' (known: q, r, p0, z0, lost_threshold, lost_steps)"),
        (lambda: registry.load_frame("sim/ungm", rng=0, q=math.inf),
         "dataset 'sim/ungm': q must be a finite number > 0 (got inf)"),
        (lambda: registry.load_frame("sim/uav-formation", rng=0, eps=1.5),
         "dataset 'sim/uav-formation': eps must be a finite number in [0, 1] (got 1.5)"),
        (lambda: registry.load_frame("sim/auv-sonar", rng=0, steps=True),
         "dataset 'sim/auv-sonar': steps must be an integer >= 1 (got true)"),
    ]
    for call, message in cases:
        with pytest.raises(ReplayError) as err:
            call()
        assert str(err.value) == message


def test_sim_parameters_reach_the_frame_with_defaults_filled_in():
    frame = registry.load_frame("sim/ungm", rng=0, q=10, steps=7)
    assert len(frame) == 7 and frame.simulation.params.q == 10.0 and frame.simulation.params.r == 1.0
    assert registry.check_params("sim/ungm", {"q": 10}) == {"steps": 100, "q": 10.0, "r": 1.0, "x0": 0.0,
                                                            "growth": 2.5}


# ---------------------------------------------------------------- CLI parsing (in process)


def test_cli_parsing():
    from replay.cli.params import dataset_params, filter_params, parse, task_params

    assert parse("resampling=systematic", "-p") == ("resampling", "systematic")
    assert parse("x0=[1, 2]", "-p") == ("x0", [1, 2])
    assert parse("z0=null", "-p") == ("z0", None)
    assert math.isnan(parse("r=NaN", "-p")[1])
    assert task_params(["r=2", "p0=0.5"], "ungm") == {"r": 2.0, "p0": 0.5}
    assert task_params(["r=2"]) == {"r": 2}
    assert dataset_params(["q=10"], "sim/ungm") == {"q": 10.0}
    assert filter_params([], ["pf"]) == {}
    with pytest.raises(ReplayError, match=r"^--task-param r: given twice \(2 and 3\)$"):
        task_params(["r=2", "r=3"])
    with pytest.raises(ReplayError, match=r"^-p pf.n_particles: given twice \(5 and 6\)$"):
        filter_params(["pf.n_particles=5", "pf.n_particles=6"], ["pf"])
    assert filter_params(["pf.resampling=multinomial", "pf.roughening=0"], ["ekf", "pf"]) == {
        "pf": {"resampling": "multinomial", "roughening": 0.0}}
    with pytest.raises(ReplayError, match=r"^--dataset-param 'q': expected NAME=VALUE$"):
        dataset_params(["q"])


def test_check_config_is_canonical_and_loads_nothing(monkeypatch):
    from replay.run.checks import check_config

    monkeypatch.setattr(registry, "load_frame", lambda *a, **k: pytest.fail("loaded data"))
    a = check_config("sim/ungm", None, ["ekf"], {}, {"r": 2}, {"q": 10})
    assert a.task == "ungm" and a.task_params == {"q": None, "r": 2.0, "p0": 1.0, "growth": None,
                                                  "lost_threshold": 10.0, "lost_steps": 10}
    assert a.dataset_params == {"steps": 100, "q": 10.0, "r": 1.0, "x0": 0.0, "growth": 2.5}
    b = check_config("sim/ungm", "ungm", ["ekf"], {"ekf": {}}, a.task_params, a.dataset_params)
    assert (b.task_params, b.dataset_params, b.filter_params) == (a.task_params, a.dataset_params, a.filter_params)
    with pytest.raises(ReplayError, match="^task 'ungm': r must be"):
        check_config("sim/ungm", None, ["ekf"], {}, {"r": 0}, {})


# ---------------------------------------------------------------- the CLI: exit 2, one line


def cli(*args, tmp_path):
    """``replay ARGS`` in process: exit status 2, one line on stderr, nothing written."""
    from click.testing import CliRunner

    from replay.cli import main

    out = tmp_path / "never"
    res = CliRunner().invoke(main, [*args, "-o", str(out)])
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert res.exit_code == 2 and isinstance(res.exception, SystemExit), (res.stderr, res.exception)
    assert len(lines) == 1 and res.stdout == "", res.output
    assert not out.exists()  # refused before any run
    return lines[0]


def cli_process(*args, tmp_path):
    """``replay ARGS`` as a user runs it: exit status 2, one line on stderr, no traceback."""
    res = subprocess.run([sys.executable, "-m", "replay.cli", *args, "-o", str(tmp_path / "never")],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert res.returncode == 2 and "Traceback" not in res.stderr and len(lines) == 1, res.stderr
    return lines[0]


SONAR = ("eval", "sim/auv-sonar", "--runs", "1")
UNGM = ("eval", "sim/ungm", "--task", "ungm", "--runs", "1", "--filters", "ekf")
BAD = [
    (SONAR + ("--filters", "pf", "-p", "pf.n_particles=1.5"), ["n_particles", "integer >= 1", "(got 1.5)"]),
    (SONAR + ("--filters", "pf", "-p", "pf.n_particles=true"), ["n_particles", "integer >= 1", "(got true)"]),
    (SONAR + ("--filters", "pf", "-p", "nofilter.x=1"), ["unknown filter 'nofilter'", "nofilter.x=1"]),
    (SONAR + ("--filters", "igwo-stcpf", "-p", "igwo_stcpf.compiled=false"),
     ["unknown filter 'igwo_stcpf'", "did you mean igwo-stcpf?", "compiled=false"]),
    (SONAR + ("--filters", "pf", "-p", "n_particles=5"), ["FILTER.NAME=VALUE", "n_particles=5"]),
    (SONAR + ("--filters", "pf", "-p", "ukf.alpha=1"), ["'ukf' is not in --filters (pf)", "ukf.alpha=1"]),
    (SONAR + ("--filters", "pf", "--dataset-param", "nope=1"), ["sim/auv-sonar", "unknown parameter 'nope'"]),
    (SONAR + ("--filters", "pf", "--dataset-param", "steps=0"), ["steps must be an integer >= 1", "(got 0)"]),
    (UNGM + ("--task-param", "r=-2"), ["task 'ungm'", "r must be a finite number > 0", "(got -2)"]),
    (UNGM + ("--task-param", "r=Infinity"), ["r must be a finite number > 0", "(got inf)"]),
    (UNGM + ("--task-param", "r=NaN"), ["r must be a finite number > 0", "(got nan)"]),
    (UNGM + ("--dataset-param", "q=-1"), ["dataset 'sim/ungm'", "q must be a finite number > 0", "(got -1)"]),
    (UNGM + ("--task-param", "nope=1"), ["task 'ungm'", "unknown parameter 'nope'"]),
]


@pytest.mark.parametrize("args, words", BAD)
def test_bad_parameters_exit_2_with_one_line(args, words, tmp_path):
    line = cli(*args, tmp_path=tmp_path)
    assert line.startswith("replay: error: ")
    for word in words:
        assert word in line, line


@pytest.mark.parametrize("case", [0, 3, 10])
@pytest.mark.slow
def test_bad_parameters_in_a_real_process(case, tmp_path):
    args, words = BAD[case]
    line = cli_process(*args, tmp_path=tmp_path)
    assert all(word in line for word in words), line


# ---------------------------------------------------------------- campaign files


CAMPAIGN = """\
[campaign]
runs = 1

[[dataset]]
id = "sim/ungm"
params = {dataset}

[task.ungm]
{task}

[[filter]]
name = "ekf"
"""


def load_campaign(tmp_path, dataset="{}", task=""):
    from replay.campaign import spec

    path = tmp_path / "c.toml"
    path.write_text(CAMPAIGN.format(dataset=dataset, task=task))
    return spec.load(path), path


@pytest.mark.parametrize("dataset, task, line, message", [
    ("{ q = -1 }", "", 6, "q: dataset 'sim/ungm': q must be a finite number > 0 (got -1)"),
    ("{ steps = 2.5 }", "", 6, "steps: dataset 'sim/ungm': steps must be an integer >= 1 (got 2.5)"),
    ("{ nope = 1 }", "", 6, "nope: dataset 'sim/ungm' has no parameter 'nope' (known: steps, q, r, x0, growth)"),
    ("{}", "r = nan", 9, "r: task 'ungm': r must be a finite number > 0 (or null) (got nan)"),
    ("{}", "p0 = true", 9, "p0: task 'ungm': p0 must be a finite number > 0 (got true)"),
])
def test_campaign_file_parameters_checked_against_declarations(tmp_path, dataset, task, line, message):
    with pytest.raises(ReplayError) as err:
        load_campaign(tmp_path, dataset, task)
    assert str(err.value) == f"{tmp_path / 'c.toml'}:{line}: {message}"


def test_campaign_configs_are_canonical(tmp_path):
    from replay.run.pipeline import config_hash

    empty, _ = load_campaign(tmp_path)
    full, _ = load_campaign(tmp_path, "{ steps = 100, q = 1, r = 1.0, x0 = 0, growth = 2.5 }", "p0 = 1")
    [a], [b] = empty.configs, full.configs
    assert a.dataset_params == {"steps": 100, "q": 1.0, "r": 1.0, "x0": 0.0, "growth": 2.5}
    assert a.task_params == {"q": None, "r": None, "p0": 1.0, "growth": None, "lost_threshold": 10.0, "lost_steps": 10}
    assert config_hash(a.as_dict()) == config_hash(b.as_dict())


def test_campaign_filter_grid_values_checked_and_params_canonical(tmp_path):
    from replay.campaign import spec
    from replay.run.pipeline import config_hash

    path = tmp_path / "c.toml"
    base = CAMPAIGN.format(dataset="{}", task="").replace('name = "ekf"', 'name = "pf"')
    path.write_text(base + "grid = { n_particles = [100, 1.5] }\n")
    with pytest.raises(ReplayError) as err:
        spec.load(path)
    assert str(err.value) == f"{path}:13: n_particles: filter 'pf': n_particles must be an integer >= 1 (got 1.5)"
    path.write_text(base)
    [a] = spec.load(path).configs
    path.write_text(base + 'params = { n_particles = 1000, resampling = "systematic" }\n')
    [b] = spec.load(path).configs
    assert a.filter_params == b.filter_params and a.filter_params["n_particles"] == 1000
    assert config_hash(a.as_dict()) == config_hash(b.as_dict())


def test_datasets_make_checks_the_generator_parameters(tmp_path):
    from click.testing import CliRunner

    from replay.cli import main

    out = tmp_path / "lake.csv"
    res = CliRunner().invoke(main, ["datasets", "make", "sim/lake-depth", "--out", str(out), "-p", "ref_every=0"])
    assert res.exit_code == 2 and not out.exists()
    assert res.stderr == "replay: error: dataset 'sim/lake-depth': ref_every must be an integer >= 1 (got 0)\n"
