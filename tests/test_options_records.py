"""Issue 37: options as declared records. EvalOptions and TuneOptions are frozen dataclasses whose fields are
their Param declarations (checked at import), each value checked when the record is made, with the one-line
messages of the declarations; the library takes them whole."""
import inspect
from dataclasses import FrozenInstanceError, dataclass, fields

import numpy as np
import pytest

from replay.run.eval_options import DEFAULTS, EVAL_OPTIONS, EvalOptions, validate_eval_options
from replay.scoring.summary import MIN_SCORED_SHARE
from replay.tune.options import TUNE_OPTIONS, TuneOptions
from replay.util.errors import ReplayError
from replay.util.params import Param, declared_fields


def test_the_records_fields_are_their_declarations_with_their_defaults():
    names = {f.name: f.default for f in fields(EvalOptions)}
    assert {p.name: p.default for p in (*EVAL_OPTIONS, MIN_SCORED_SHARE)}.items() <= names.items()
    assert names["runs"] == DEFAULTS["runs"] == 1 and names["batch"] == 25 and names["alignment"] == "se3"
    tune = {f.name: f.default for f in fields(TuneOptions)}
    assert {p.name: p.default for p in TUNE_OPTIONS}.items() <= tune.items()
    assert tune["runs"] == 20 and tune["trials"] == 50 and tune["batch"] is None  # replay tune's defaults


def test_a_record_that_drifts_from_its_declarations_is_refused_at_import():
    @dataclass(frozen=True)
    class Drifted:
        runs: int = 2  # the declaration says 1

    with pytest.raises(TypeError, match=r"Drifted\.runs: not a field defaulting to its declaration's 1"):
        declared_fields(Drifted, (Param("runs", int, 1, "runs", low=1),))
    with pytest.raises(TypeError, match=r"Drifted\.seed"):
        declared_fields(Drifted, (Param("seed", int, 0, "seed"),))


@pytest.mark.parametrize("name,value", [("runs", 0), ("seed", -1), ("alignment", "affine"), ("batch", 1.5),
                                        ("divergence_threshold", 0.0), ("first", 0), ("task_params", [1])])
def test_a_bad_option_is_the_declarations_one_line(name, value):
    with pytest.raises(ReplayError) as want:
        validate_eval_options({name: value})
    with pytest.raises(ReplayError) as got:
        EvalOptions(**{name: value})
    assert str(got.value) == str(want.value) and "\n" not in str(got.value)


def test_values_are_normalised_and_the_record_is_frozen():
    o = EvalOptions(seed=np.int64(3), divergence_threshold=50, min_scored_share=1)
    assert type(o.seed) is int and o.seed == 3
    assert type(o.divergence_threshold) is float and o.divergence_threshold == 50.0
    assert type(o.min_scored_share) is float
    with pytest.raises(FrozenInstanceError):
        o.runs = 5
    with pytest.raises(ReplayError, match=r"^min_scored_share must be a finite number in \[0, 1\] \(got 2\)$"):
        EvalOptions(min_scored_share=2)


def test_tune_options_keep_their_messages():
    base = dict(filters=["kf"], entries=[])
    with pytest.raises(ReplayError, match=r"^--trials 0: at least 1 trial per filter$"):
        TuneOptions(trials=0, **base)
    with pytest.raises(ReplayError, match=r"^runs must be an integer in \[1, 1000000\] \(got 0\)$"):
        TuneOptions(runs=0, **base)
    with pytest.raises(ReplayError, match=r"^allow_overlap must be true or false \(got 1\)$"):
        TuneOptions(allow_overlap=1, **base)
    assert TuneOptions(first=np.int64(100), **base).first == 100


def test_the_library_takes_the_records_whole():
    from replay.campaign import execute
    from replay.run.evaluation import evaluate
    from replay.tune.check import prepare

    assert list(inspect.signature(evaluate).parameters) == ["dataset", "options", "progress"]
    assert list(inspect.signature(prepare).parameters) == ["o"]
    assert list(inspect.signature(execute.run).parameters) == ["campaign", "out", "options"]


def test_a_simulators_record_holds_its_declared_values():
    from replay.sim import generator

    seen = []

    @generator((Param("steps", int, 5, "steps", low=1), Param("dt", float, 0.5, "step")), record=True)
    def make_frame(rng, p):
        seen.append(p)
        return p.steps * p.dt

    assert make_frame(None, steps=4) == 2.0
    assert (seen[0].steps, seen[0].dt) == (4, 0.5) and type(seen[0].dt) is float
    with pytest.raises(FrozenInstanceError):
        seen[0].steps = 1
    with pytest.raises(ReplayError, match=r"steps must be an integer >= 1 \(got 0\)"):
        make_frame(None, steps=0)
