"""A misbehaving filter plugin (issue 23 item 8): its failure is its own failed runs with the
error recorded, the other filters' results are written; shapes are checked at the protocol
boundary; memory that cannot be had is refused before the run or reported as such."""
from __future__ import annotations

import csv
import json
import sys
import textwrap

import numpy as np
import pytest

import replay
from hostile import assert_refused, invoke, register
from replay.filters import FILTERS
from replay.run.resources import check_kept, check_particles
from replay.util.errors import ReplayError

SONAR = {"runs": 2, "dataset_params": {"steps": 30}}
PLUGIN = """
import sys
import numpy as np
from replay.filters import Filter

class Walk(Filter):
    name = "walk"
    def predict(self, state, k):
        state.x = state.model.f(state.x, k)
        state.P = state.P + state.model.process_cov(k)
    def update(self, state, z, k, mask):
        pass

class TypeErr(Walk):
    def predict(self, state, k):
        raise TypeError("boom in predict")

class Exits(Walk):
    def predict(self, state, k):
        sys.exit(0)

class WrongShape(Walk):
    def estimate(self, state):
        return state.x, state.P[:1, :1]  # would broadcast into the (6, 6) covariance

class NoMemory(Walk):
    def predict(self, state, k):
        raise MemoryError("cannot allocate the particles")

class FewerRuns(Walk):
    def run_batch(self, model, Z, X0, P0, rngs):
        return super().run_batch(model, Z, X0, P0, rngs)[:1]

class ExitsAtInit(Walk):
    def __init__(self, **params):
        sys.exit(0)

class RaisesAtInit(Walk):
    def __init__(self, **params):
        raise RuntimeError("no licence")

class BadParams(Walk):
    def params(self):
        raise KeyError("gain")

class BatchHungry(Walk):
    '''Runs out of memory with more than one run at once: redone run by run (the same numbers).'''
    def engine(self, model, rngs):
        if len(rngs) > 1:
            raise MemoryError("a batch is too big")
        return super().engine(model, rngs)
"""
CASES = {
    "TypeErr": "TypeError: boom in predict",
    "Exits": r"the filter called sys.exit\(0\)",
    "WrongShape": r"filter WrongShape: estimate\(\) returned a state of shape \(6,\) and a covariance of "
                  r"shape \(1, 1\); expected \(6,\) and \(6, 6\)",
    "NoMemory": "out of memory",
    "FewerRuns": r"run_batch\(\) returned 1 results for 2 runs",
}


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    (tmp_path / "badplug.py").write_text(textwrap.dedent(PLUGIN))
    monkeypatch.syspath_prepend(str(tmp_path))
    before = set(FILTERS._session)  # noqa: SLF001
    yield
    sys.modules.pop("badplug", None)
    for name in set(FILTERS._session) - before:  # noqa: SLF001 — the classes registered by evaluate(filters=[cls])
        FILTERS.unregister(name)


@pytest.mark.parametrize("cls", sorted(CASES))
def test_a_failing_plugin_is_its_failed_runs_and_the_built_ins_are_written(plugin, tmp_path, cls):
    out = tmp_path / "o"
    res = invoke(["eval", "sim/auv-sonar", "--filters", f"ekf,badplug:{cls}", "--runs", "2",
                  "--dataset-param", "steps=30", "-q", "-o", out])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    assert res.exit_code == 1, res.output
    warn = [ln for ln in res.stderr.splitlines() if ln.startswith("replay: warning: ")]
    assert len(warn) == 1 and f"filter 'badplug:{cls}': 2 of 2 runs failed" in warn[0]
    import re

    assert re.search(CASES[cls], warn[0]), warn[0]
    rows = {r["filter"]: r for r in csv.DictReader(open(out / "leaderboard.csv"))}
    assert rows[f"badplug:{cls}"]["failed"] == "2" and rows[f"badplug:{cls}"]["runs"] == "0"
    assert rows["ekf"]["failed"] == "0" and rows["ekf"]["runs"] == "2"
    man = json.loads((out / "manifest.json").read_text())
    assert man["failures"][f"badplug:{cls}"]["runs"] == [0, 1]
    assert re.search(CASES[cls], man["failures"][f"badplug:{cls}"]["error"])
    alone = replay.evaluate("sim/auv-sonar", filters=["ekf"], **SONAR)
    assert float(rows["ekf"]["pos_rmse"]) == pytest.approx(alone.rows[0]["pos_rmse"], rel=1e-5)
    assert (out / "estimates" / "ekf.csv.gz").exists()


def test_a_failing_filter_in_the_api_and_a_wrong_shape_never_reaches_nees(plugin):
    import badplug

    ev = replay.evaluate("sim/auv-sonar", filters=["ekf", badplug.WrongShape], **SONAR)
    bad = ev.results[1]
    assert [r.status for r in bad.records] == ["failed", "failed"] and np.isnan(ev.rows[1]["pos_rmse"])
    assert np.isnan(bad.estimates[0].P).all() and bad.estimates[0].P.shape == (30, 6, 6)
    assert not ev.rows[1]["nees"] == ev.rows[1]["nees"]  # NaN: no NEES from a broadcast covariance
    assert len(ev.estimates("wrongshape")) == 60  # the tables keep one entry per run and step


def test_memory_error_of_a_batch_is_redone_run_by_run_with_the_same_numbers(plugin):
    import badplug

    ev = replay.evaluate("sim/auv-sonar", filters=[badplug.BatchHungry], **SONAR)
    assert ev.rows[0]["failed"] == 0 and ev.rows[0]["runs"] == 2
    one = [replay.evaluate("sim/auv-sonar", filters=[badplug.Walk], runs=1, seed=0,
                           dataset_params={"steps": 30})]
    assert ev.results[0].runs[0]["pos_rmse"] == one[0].results[0].runs[0]["pos_rmse"]


def test_particles_that_cannot_fit_are_refused_before_the_run(tmp_path):
    line = assert_refused(["eval", "sim/auv-sonar", "--filters", "ekf,pf", "--runs", "2", "-o", tmp_path / "o",
                           "-p", "pf.n_particles=1000000000000"], r"-p pf\.n_particles = 1000000000000: ")
    assert "of memory" in line and "available" in line and not (tmp_path / "o").exists()
    with pytest.raises(ReplayError, match=r"^-p pf\.n_particles = 1000000000000: the particles need about 960\.0 TB"):
        check_particles("pf", {"n_particles": 10 ** 12}, 20, 6, avail=10 ** 9)
    check_particles("pf", {"n_particles": 1000}, 25, 6, avail=10 ** 9)  # 1.2 MB: fine


def test_runs_whose_estimates_cannot_be_kept_are_refused(tmp_path):
    assert_refused(["eval", "sim/auv-sonar", "--filters", "ekf", "--runs", "1000000000", "-o", tmp_path / "o"],
                   r"^replay: error: runs must be an integer in \[1, 1000000\] \(got 1000000000\)$")
    with pytest.raises(ReplayError, match=r"^runs = 1000000: replay eval keeps every run's estimates in memory"):
        check_kept(4, 1_000_000, 100, 6, avail=10 ** 9)
    check_kept(4, 100, 100, 6, avail=10 ** 9)


@pytest.mark.parametrize("cls,match", [
    ("ExitsAtInit", r"filter 'badplug:ExitsAtInit': its constructor failed: SystemExit: 0$"),
    ("RaisesAtInit", r"filter 'badplug:RaisesAtInit': its constructor failed: RuntimeError: no licence$"),
    ("BadParams", r"filter 'badplug:BadParams': params\(\) failed: KeyError: 'gain'$")])
def test_a_plugin_failing_before_any_run_is_refused_in_one_line(plugin, tmp_path, cls, match):
    assert_refused(["eval", "sim/auv-sonar", "--filters", f"ekf,badplug:{cls}", "-o", tmp_path / "o"], match)
    assert not (tmp_path / "o").exists()


def test_an_unpredicted_memory_error_is_out_of_memory_not_a_traceback(monkeypatch, tmp_path):
    import replay.outputs.eval_job as job
    import replay.run.evaluation as module

    def hungry(*a, **k):
        raise MemoryError("Unable to allocate 9.1 TiB")

    monkeypatch.setattr(module, "evaluate", hungry)
    monkeypatch.setattr(job, "evaluate", hungry)  # replay eval's one call binds it at import
    assert_refused(["eval", "sim/auv-sonar", "--filters", "ekf", "-o", tmp_path / "o"],
                   r"^replay: error: out of memory \(Unable to allocate 9\.1 TiB\)$")
    with pytest.raises(ReplayError, match=r"^replay\.evaluate: out of memory \(MemoryError: Unable to allocate"):
        replay.evaluate("sim/auv-sonar", filters=["ekf"])


@pytest.mark.parametrize("cls", ["Exits", "TypeErr", "NoMemory"])
def test_a_campaign_unit_records_the_plugins_failure(plugin, cls):
    from replay.run.pipeline import Config, run_block

    cfg = Config("sim/auv-sonar", {"steps": 30}, None, "sonar", {}, f"badplug:{cls}", {}, 0)
    recs = run_block(cfg, [0, 1, 2])  # a campaign's job: never raises for one run
    assert [r.status for r in recs] == ["failed"] * 3 and [r.run for r in recs] == [0, 1, 2]
    import re

    assert all(re.search(CASES[cls], r.error) for r in recs)


def test_keyboard_interrupt_is_not_a_failed_run():
    from replay.run.failures import ends_run

    assert ends_run(KeyboardInterrupt(), strict=False) and not ends_run(SystemExit(0), strict=True)
    assert ends_run(ReplayError("x"), strict=True) and not ends_run(ReplayError("x"), strict=False)


register("plugin-typeerror", "plugin-sys-exit-0", "plugin-wrong-covariance-shape", "plugin-memory-error",
         "plugin-fewer-runs", "pf-n-particles-1e12", "plugin-sys-exit-in-constructor", "plugin-params-raise",
         "eval-memory-error")
