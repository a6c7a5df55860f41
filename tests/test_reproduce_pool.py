"""The reproductions' worker pool (replay.campaign.longest): the costliest evaluation first, the serial
results whatever the workers, ``REPLAY_WORKERS`` read in one line; paper 002's jobs through it."""
from __future__ import annotations

import os

import numpy as np
import pytest

from replay.campaign import longest as pool
from replay.reproduce import p002
from replay.util.errors import ReplayError


def square_and_pid(x):
    return x * x, os.getpid()


def test_longest_first_orders_by_cost_ties_in_list_order():
    assert pool.longest_first([3.0, 10.0, 3.0, 0.5, 10.0]) == [1, 4, 0, 2, 3]


def test_workers_from_the_environment(monkeypatch):
    monkeypatch.delenv("REPLAY_WORKERS", raising=False)
    assert pool.workers() == 2
    monkeypatch.setenv("REPLAY_WORKERS", "0")
    assert pool.workers() == 1
    monkeypatch.setenv("REPLAY_WORKERS", "two")
    with pytest.raises(ReplayError, match=r"^REPLAY_WORKERS must be a whole number of worker processes \(got 'two'\)$"):
        pool.workers()


def test_serial_runner_goes_longest_first_and_reports_each(capsys):
    got = list(pool.run_longest_first(square_and_pid, [1, 2, 3], [1.0, 5.0, 2.0], ["a", "b", "c"], prefix="p: "))
    assert [i for i, _ in got] == [1, 2, 0] and [r[0] for _, r in got] == [4, 9, 1]
    assert {r[1] for _, r in got} == {os.getpid()}  # one worker: this process
    err = capsys.readouterr().err.splitlines()
    assert [line.split(" (")[0] + ", " + line.split(", ")[-1] for line in err] == [
        "p: reproduce: 1/3 jobs, b done", "p: reproduce: 2/3 jobs, c done", "p: reproduce: 3/3 jobs, a done"
    ]  # tqdm's lines off a terminal: one per job, the costliest first
    assert "(62 % of the work)" in err[0] and "(100 % of the work)" in err[2]  # weighted by the costs 5, 2, 1


@pytest.mark.slow
def test_pool_runs_in_other_processes_with_the_serial_results():
    costs = [float(c) for c in (3, 9, 1, 7, 5, 2)]
    with pool.pool(2) as ex:
        got = dict(pool.run_longest_first(square_and_pid, list(range(6)), costs, list("abcdef"), ex, quiet=True))
    assert {i: r[0] for i, r in got.items()} == {i: i * i for i in range(6)}
    assert os.getpid() not in {r[1] for r in got.values()}


def without_timing(ev):
    """The rows (NaN as a string, so that equal rows compare equal) without the timing, and the estimates."""
    rows = [{k: "nan" if isinstance(v, float) and np.isnan(v) else v for k, v in r.items()
             if "us_per_step" not in k and "seconds" not in k} for r in ev.rows]
    return rows, [[e.x for e in res.estimates] for res in ev.results]


@pytest.mark.slow
def test_p002_jobs_in_two_workers_equal_the_serial_run():
    """Two small experiments of the paper-002 reproduction, serial and in a pool of two: the same
    per-run values, lost flags and leaderboard rows but the timing (each evaluation draws from its own
    seeded streams), keyed by experiment and row."""
    defaults = p002.load()["defaults"]  # the rows and experiments as 002.toml's entries are completed
    row = lambda label, params, flt=None: p002.row({**defaults["row"], "label": label, "filter": flt or label,
                                                    "params": params})
    exp = lambda key, dataset, task, rows, dp=None: {**defaults["exp"], "key": key, "group": key, "dataset": dataset,
                                                     "task": task, "rows": rows, "dp": dp or {}}
    exps = [exp("u", "sim/ungm", "ungm", [row("igwo-pf", {"t_max": 3}), row("pf (N = 50)", {"n_particles": 50}, "pf")]),
            exp("s", "sim/auv-sonar", "sonar", [row("stcpf", {"n_particles": 20}),
                                                 row("pso-pf", {"n_particles": 20, "t_max": 3})], {"steps": 15})]
    s = {"seed": 3, "data_dir": None, "quiet": True, "mc": 2, "tune": 2, "bohai": 2, "above": p002.load()["above"]}
    serial = p002.run_all(exps, s, None)
    with pool.pool(2) as ex:
        parallel = p002.run_all(exps, s, ex)
    assert sorted(serial) == sorted(parallel) == ["cmd:s", "cmd:u", "s", "u"]
    assert sorted(serial["u"]) == ["igwo-pf", "pf (N = 50)"]
    for key in ("u", "s"):
        for label, a in serial[key].items():
            b = parallel[key][label]
            a["row"].pop("us_per_step"), b["row"].pop("us_per_step")
            assert repr(a) == repr(b), label  # NaN-safe: the same text
            assert len(a["v"]["pos_rmse"]) == 2 and np.isfinite(a["v"]["pos_rmse"]).all()
