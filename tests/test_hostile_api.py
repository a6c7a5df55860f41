"""The Python API under bad arguments (calls generated from the declarations) and eval options
validated as the CLI validates them: every bad call is one-line ReplayError, before any work."""
from __future__ import annotations

import inspect
import math
import os

import numpy as np
import pytest

import replay
from hostile import assert_refused, register
from replay.api_args import ARGS, CLOSED, Either, Kind, Several
from replay.run.eval_options import EVAL_OPTIONS, validate_eval_options
from replay.util.errors import ReplayError

SONAR = {"dataset_params": {"steps": 10}}


def bad_values(decl) -> list:
    """Wrong types and out-of-range values of a declaration (Param, Kind, or Either: those no option accepts)."""
    if isinstance(decl, Either):
        return [v for d in decl.options for v in bad_values(d) if not _accepted(decl, v)]
    if isinstance(decl, Several):  # a bad item alone and in a list, and an empty list
        return [v for v in [*bad_values(decl.item), [], [bad_values(decl.item)[-1]]] if not _accepted(decl, v)]
    if isinstance(decl, Kind):
        return [3, "x", object()] + ([] if decl.optional else [None])
    t, out = decl.type, ([] if decl.optional else [None])
    if t is int:
        out += [1.5, "3", True, np.bool_(True), [1], float("nan")]
        out += [decl.low - 1] if decl.low is not None else []
        out += [decl.high + 1] if decl.high is not None else []
    elif t is float:
        out += ["x", True, float("nan"), [1.0]] + ([float("inf")] if decl.finite else [])
        out += [decl.low - 1] + ([decl.low] if decl.low_open else []) if decl.low is not None else []
        out += [decl.high + 1] if decl.high is not None else []
    elif t is bool:
        out += [1, 0, "true", 1.0]
    elif t is str:
        out += [3, b"x", ["a"]] + (["not-a-choice"] if decl.choices else [])
    elif t is dict:
        out += [3, "x", [1], {1: 2}]
    elif t is os.PathLike:
        out += [3, "", b"x", ["a"], "a\0b"]
    elif t is list:
        out += [3, "x", ["a"]]
    return out


def _accepted(decl, value) -> bool:
    try:
        decl.check(value)
        return True
    except ReplayError:
        return False


@pytest.fixture(scope="module")
def subjects(tmp_path_factory):
    """A declaration-valid call of each public function: (args, kwargs); paths in a temporary directory."""
    from replay.filters.kalman import EKF
    from replay.tasks import TASKS
    from replay.trajectory.base import make

    ev = replay.evaluate("sim/auv-sonar", filters=["ekf"], runs=1, **SONAR)
    frame = replay.load_frame("sim/auv-sonar", seed=0, steps=10)
    tmp = tmp_path_factory.mktemp("api")
    t = np.arange(5.0)
    traj = make(t, np.column_stack([t, t, t]), source="t")
    return {
        "evaluate": (("sim/auv-sonar",), {"filters": ["ekf"], **SONAR}),
        "load_frame": (("sim/auv-sonar",), {}),
        "campaign_results": ((tmp / "somewhere",), {}),
        "export_mcap": ((ev, tmp / "x.mcap"), {}),
        "frame_table": ((frame,), {}), "report_table": ((frame,), {}),
        "make_filter": (("ekf",), {}), "make_task": (("sonar",), {}),
        "plot_errors": ((ev,), {}), "plot_paired": ((ev,), {}), "plot_rmse": ((ev,), {}),
        "plot_track": ((ev,), {}),
        "register_filter": ((EKF,), {}), "register_task": ((TASKS.load("sonar"),), {}),
        "run_campaign": ((tmp / "c.toml",), {"out": tmp / "o"}),
        "load_trajectory": ((tmp / "x.txt",), {}),
        "score": ((traj, traj), {}),
        "list_plugins": ((), {}), "refresh_plugins": ((), {}),
    }


def generated_calls():
    for fn, decls in sorted(ARGS.items()):
        for arg, decl in decls.items():
            for value in bad_values(decl):
                yield pytest.param(fn, arg, value, id=f"{fn}-{arg}-{value!r:.20}")


def test_every_public_function_is_declared_and_its_declarations_are_its_arguments():
    from dataclasses import fields

    from replay.run.eval_options import EvalOptions

    assert set(ARGS) == set(replay.__all__)
    for fn, decls in ARGS.items():
        params = inspect.signature(getattr(replay, fn)).parameters
        extra = {"evaluate": {f.name for f in fields(EvalOptions)}}.get(fn, {})  # the record replay.evaluate builds
        if fn == "score":  # its options are its declarations, taken whole as keywords (closed: no other)
            extra = {k for k in decls if params["options"].kind is inspect.Parameter.VAR_KEYWORD}
        assert set(decls) <= set(params) | set(extra), (fn, set(decls) - set(params) - set(extra))
    score = inspect.signature(replay.score).parameters  # every option of replay.score is declared
    assert list(score) == ["reference", "estimates", "options"] and CLOSED["score"] == ()
    with pytest.raises(ReplayError, match=r"^replay\.score: unknown option 'nope' \(known: .*pose_relation"):
        replay.score("a.tum", "b.tum", nope=1)


@pytest.mark.parametrize("fn,arg,value", list(generated_calls()))
def test_generated_bad_call_is_one_line_replay_error(subjects, fn, arg, value):
    args, kwargs = subjects[fn]
    names = list(inspect.signature(getattr(replay, fn)).parameters)
    args = list(args)
    if arg in names[:len(args)]:
        args[names.index(arg)] = value
    else:
        kwargs = dict(kwargs, **{arg: value})
    with pytest.raises(ReplayError) as err:
        getattr(replay, fn)(*args, **kwargs)
    text = str(err.value)
    assert text and "\n" not in text and arg in text, text


def test_generated_cases_are_many():
    assert len(list(generated_calls())) > 250


@pytest.mark.parametrize("fn", sorted(ARGS))
def test_wrong_arity_and_unknown_keyword_are_one_line(fn):
    f = getattr(replay, fn)
    with pytest.raises(ReplayError, match=rf"^replay\.{fn}: ") as err:
        f(*range(len(inspect.signature(f).parameters) + 3))
    assert "\n" not in str(err.value)


def test_issue_example_runs_0_and_seed_minus_1_same_line_as_the_cli(tmp_path):
    cases = [({"runs": 0}, ["--runs", "0"]), ({"seed": -1}, ["--seed", "-1"]),
             ({"divergence_threshold": -1.0}, ["--divergence-threshold", "-1"]),
             ({"runs": 10 ** 9}, ["--runs", str(10 ** 9)]), ({"alignment": "so3"}, ["--alignment", "so3"]),
             ({"first": 0}, ["--first", "0"])]
    for api, cli in cases:
        with pytest.raises(ReplayError) as err:
            replay.evaluate("sim/auv-sonar", filters=["ekf"], **api)
        line = assert_refused(["eval", "sim/auv-sonar", "--filters", "ekf", "-o", tmp_path / "o", *cli], "must be")
        assert line == f"replay: error: {err.value}"
        assert not (tmp_path / "o").exists()


def test_one_declaration_validates_options_for_campaign_files():
    assert validate_eval_options({"seed": np.int64(3), "divergence_threshold": 5}) == {
        "seed": 3, "divergence_threshold": 5.0}
    with pytest.raises(ReplayError, match=r"^c\.toml: divergence_threshold must be a finite number > 0"):
        validate_eval_options({"divergence_threshold": -1.0}, "c.toml")
    with pytest.raises(ReplayError, match=r"^c\.toml: unknown option 'sed'"):
        validate_eval_options({"sed": 1}, "c.toml")
    for p in EVAL_OPTIONS:  # every default is accepted by its own declaration
        assert validate_eval_options({p.name: p.default})[p.name] == p.default
    seed = next(p for p in EVAL_OPTIONS if p.name == "seed")
    assert seed.accepts() == "an integer in [0, 9223372036854775807]"  # exact, not 9.22337e+18


def test_api_normalises_options_as_the_cli_does():
    a = replay.evaluate("sim/auv-sonar", filters=["ekf"], divergence_threshold=50, seed=np.int64(2), **SONAR)
    b = replay.evaluate("sim/auv-sonar", filters=["ekf"], divergence_threshold=50.0, seed=2, **SONAR)
    assert a.results[0].config_hash == b.results[0].config_hash
    assert a.rows[0]["pos_rmse"] == b.rows[0]["pos_rmse"] and not math.isnan(a.rows[0]["pos_rmse"])


def test_relations_unknown_options_and_names(subjects):
    ev = subjects["plot_rmse"][0][0]
    for call, match in [
        (lambda: replay.plot_track(ev, run=5), r"^replay\.plot_track: run 5: the evaluation has runs 0\.\.0$"),
        (lambda: replay.export_mcap(ev, "never.mcap", run=1), r"^replay\.export_mcap: run 1: "),
        (lambda: replay.plot_rmse(ev, metric="nosuch"), r"^replay\.plot_rmse: metric 'nosuch' is not a leaderboard"),
        (lambda: replay.evaluate("sim/auv-sonar", filters=["ekf"], sed=1), r"^replay\.evaluate: unknown option 'sed' "
                                                                           r"\(known: task, runs, seed,"),
        (lambda: replay.evaluate("sim/auv-sonar", filters=["ekf"], adapter="nosuch"), r"^unknown adapter 'nosuch'"),
        (lambda: replay.evaluate("sim/auv-sonar", filters=["ekf"], filter_params={"ekf": 3}), r"^filter_params must"),
        (lambda: replay.load_frame("sim/auv-sonar", seed=-1), r"^seed must be an integer in \[0, 9223372036854775807\] "
                                                               r"or a numpy\.random\.Generator"),
    ]:
        with pytest.raises(ReplayError, match=match) as err:
            call()
        assert "\n" not in str(err.value)
    assert not os.path.exists("never.mcap")
    for n in (0, 1.5, True, None):
        with pytest.raises(ReplayError, match=r"^runs must be an integer in \[1, 1000000\]"):
            ev.first(n)
    frame = replay.load_frame("sim/auv-sonar", seed=np.random.default_rng(1), steps=5)  # a Generator is a seed
    assert len(frame.t) == 5


register("api-generated-bad-arguments", "api-runs-0", "eval-seed-minus-1", "api-seed-minus-1",
         "api-divergence-threshold-negative", "eval-runs-1e9")
