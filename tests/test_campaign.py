"""Campaigns: resumable, atomic, backend-independent, validated before any work."""
import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from replay.campaign import board, execute, spec
from replay.cli import main
from replay.scoring.record import RunRecord
from replay.util.errors import ReplayError

SMALL = """\
[campaign]
name = "small"
runs = 6
seed = 3
batch = 3
alignment = "se3"

[[dataset]]
id = "sim/auv-sonar"
tasks = ["sonar"]
params = { steps = 30 }

[[filter]]
name = "ekf"

[[filter]]
name = "ukf"
grid = { alpha = [0.5, 1.0] }

[[filter]]
name = "pf"
params = { n_particles = 60 }
"""


def write(tmp_path, text, name="c.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def board_rows(out):
    """Leaderboard without the columns that are not results (timing, version)."""
    with open(Path(out) / "leaderboard.csv") as fh:
        return [{k: v for k, v in r.items() if k not in ("us_per_step", "version")} for r in csv.DictReader(fh)]


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    d = tmp_path_factory.mktemp("serial")
    c = spec.load(write(d, SMALL))
    counts = execute.run(c, d / "out", execute.RunOptions(workers=1, quiet=True))
    return d / "out", counts


def test_campaign_runs_every_unit_then_does_no_work(serial, tmp_path):
    out, counts = serial
    assert counts["units"] == 4 * 6 and counts["done"] == 24 and counts["failed"] == 0
    rows = board_rows(out)
    assert [r["label"] for r in rows] == ["ekf", "ukf(alpha=0.5)", "ukf(alpha=1.0)", "pf"]  # campaign file order
    assert all(r["runs"] == "6" and r["task"] == "sonar" for r in rows)
    again = execute.run(spec.load(write(tmp_path, SMALL)), out, execute.RunOptions(workers=1, quiet=True))
    assert again["units"] == 0 and again["stored_before"] == 24
    assert board_rows(out) == rows


def test_campaign_numbers_equal_replay_eval(serial):
    """The campaign's (batched) runs give `replay eval`'s (one-by-one) numbers."""
    from replay import evaluate  # the API: keywords in, one EvalOptions record built

    out, _ = serial
    ev = evaluate("sim/auv-sonar", filters=["ekf", "ukf", "pf"], runs=6, seed=3, dataset_params={"steps": 30},
                  filter_params={"pf": {"n_particles": 60}})
    rows = {r["label"]: r for r in board.read_dir(out)}
    for name, label in (("ekf", "ekf"), ("ukf", "ukf(alpha=0.5)"), ("pf", "pf")):
        res = next(r for r in ev.results if r.name == name)
        assert rows[label]["pos_rmse"] == pytest.approx(res.summary["pos_rmse"], rel=1e-9)
        assert rows[label]["yaw_rmse"] == pytest.approx(res.summary["yaw_rmse"], rel=1e-9)


def test_interrupted_and_resumed_equals_uninterrupted(serial, tmp_path):
    out = tmp_path / "out"
    c = spec.load(write(tmp_path, SMALL))
    first = execute.run(c, out, execute.RunOptions(workers=1, quiet=True, limit=3))
    assert first["units"] == 9
    # debris of a run killed while writing: a temporary file and a table without its record
    store = board.Store(out)
    h = next(h for h, _ in store.configs() if 5 not in store.stored_runs(h))
    (out / "units" / h / ".5.parquet.123.tmp").write_bytes(b"half")
    (out / "units" / h / "5.parquet").write_bytes(b"half-written")
    rest = execute.run(c, out, execute.RunOptions(workers=2, quiet=True))  # resumed on a process pool
    assert rest["units"] == 15 and rest["backend"].startswith("processes")
    assert board_rows(out) == board_rows(serial[0])


def test_block_resumed_with_one_run_left_equals_uninterrupted(serial, tmp_path):
    """The case a kill leaves at random: one run of a batched block missing. It is computed
    alone on resume and must give the numbers of the whole block (Kalman filters: also the NIS)."""
    import shutil

    out = tmp_path / "out"
    shutil.copytree(serial[0], out)
    store = board.Store(out)
    for h, cfg in store.configs():
        if cfg["filter"] in ("ukf", "ekf"):
            (out / "units" / h / "4.json").unlink()
            (out / "units" / h / "4.parquet").unlink()
    rest = execute.run(spec.load(write(tmp_path, SMALL)), out, execute.RunOptions(workers=1, quiet=True))
    assert rest["units"] == 3
    assert board_rows(out) == board_rows(serial[0])


@pytest.mark.slow
def test_killed_subprocess_resumes_to_identical_results(serial, tmp_path):
    path = write(tmp_path, SMALL)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "replay.cli", "campaign", "run", str(path), "-o", str(out), "-w", "1", "-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(list(out.glob("units/*/[0-9]*.json"))) < 3:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    stored = len(list(out.glob("units/*/[0-9]*.json")))
    assert 0 < stored < 24, stored
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert f"{24 - stored} units computed" in res.stdout
    assert board_rows(out) == board_rows(serial[0])


@pytest.mark.slow
def test_dask_local_cluster_equals_serial(serial, tmp_path):
    pytest.importorskip("distributed")
    c = spec.load(write(tmp_path, SMALL))
    counts = execute.run(c, tmp_path / "out", execute.RunOptions(dask_local=2, quiet=True))
    assert counts["backend"] == "dask" and counts["done"] == 24
    assert board_rows(tmp_path / "out") == board_rows(serial[0])


@pytest.mark.slow
def test_unanswering_scheduler_fails_fast_with_one_line(tmp_path):
    pytest.importorskip("distributed")
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there
    res = CliRunner().invoke(main, ["campaign", "run", str(write(tmp_path, SMALL)), "-o", str(tmp_path / "o"),
                                    "--scheduler", f"tcp://127.0.0.1:{port}", "-q"])
    assert res.exit_code == 2, res.output
    assert "no answer within 5 s" in res.output and "Traceback" not in res.output


def test_exception_inside_a_filter_is_that_runs_divergence(tmp_path, monkeypatch):
    # An exception inside the PF's numeric step (its resampling raises) is a divergence of
    # the run, recorded with its error; the other filters and the campaign go on.
    from replay.filters import resampling

    def broken(w, rng, n=None):
        raise KeyError("nope")

    plan = spec.load(write(tmp_path, SMALL))
    monkeypatch.setitem(resampling.SCHEMES, "systematic", broken)
    out = tmp_path / "out"
    counts = execute.run(plan, out, execute.RunOptions(workers=1, quiet=True))
    assert counts["failed"] == 0 and counts["done"] == 24
    rows = {r["label"]: r for r in board_rows(out)}
    assert rows["pf"]["diverged"] == "6" and rows["pf"]["runs"] == "6" and rows["pf"]["pos_rmse"] == "nan"
    assert rows["ekf"]["diverged"] == "0" and rows["ekf"]["runs"] == "6"
    recs = [json.loads(p.read_text()) for p in out.glob("units/*/[0-9]*.json")]
    pf = [r for r in recs if "error" in r["metrics"]]
    assert len(pf) == 6 and all(r["metrics"]["error"] == "KeyError: 'nope'" for r in pf)
    assert all(r["metrics"]["diverged_at"] == 0 for r in pf)


def test_failing_unit_is_recorded_and_campaign_goes_on(tmp_path, monkeypatch):
    # A run whose problem cannot be built is recorded as failed, with its error; the rest go on.
    from replay.run import pipeline

    build = pipeline.build_problem

    def flaky(config, run, *args):
        if run == 2:
            raise KeyError("nope")
        return build(config, run, *args)

    plan = spec.load(write(tmp_path, SMALL))
    monkeypatch.setattr(pipeline, "build_problem", flaky)
    out = tmp_path / "out"
    counts = execute.run(plan, out, execute.RunOptions(workers=1, quiet=True))
    assert counts["failed"] == 4 and counts["done"] == 20
    rows = board_rows(out)
    assert all(r["failed"] == "1" and r["runs"] == "5" for r in rows)
    recs = [json.loads(p.read_text()) for p in out.glob("units/*/[0-9]*.json")]
    failed = [r for r in recs if r["status"] == "failed"]
    assert len(failed) == 4 and all(r["run"] == 2 and "KeyError" in r["error"] for r in failed)


@pytest.mark.parametrize("edit,line,needle", [
    (('id = "sim/auv-sonar"', 'id = "sim/auv-sonnar"'), 9, "unknown dataset"),
    (('tasks = ["sonar"]', 'tasks = ["sonr"]'), 10, "unknown task 'sonr'"),
    (('name = "ukf"', 'name = "xkf"'), 17, "unknown filter 'xkf'"),
    (("grid = { alpha = [0.5, 1.0] }", "grid = { alpa = [0.5, 1.0] }"), 18, "no parameter 'alpa'"),
    (("grid = { alpha = [0.5, 1.0] }", "grid = { alpha = [] }"), 18, "empty grid"),
    (("n_particles = 60", 'n_particles = "many"'), 22, "n_particles must be an integer >= 1 (got 'many')"),
    (("runs = 6", 'runs = "6"'), 3, "runs must be an integer in [1, 1000000] (got '6')"),
    (("batch = 3", "bacth = 3"), 5, "bacth: unknown key"),
])
def test_bad_campaign_refused_before_work_with_file_and_line(tmp_path, edit, line, needle):
    path = write(tmp_path, SMALL.replace(*edit))
    with pytest.raises(ReplayError) as err:
        spec.load(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}:{line}: ") and needle in msg and "\n" not in msg
    res = CliRunner().invoke(main, ["campaign", "run", str(path), "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and not (tmp_path / "o").exists()


def test_leaderboard_command_merges_and_sorts(serial, tmp_path):
    out = serial[0]
    ev = tmp_path / "ev"
    res = CliRunner().invoke(main, ["eval", "sim/auv-sonar", "-f", "ckf", "--runs", "2", "-o", str(ev)])
    assert res.exit_code == 0, res.output
    merged = tmp_path / "merged.csv"
    res = CliRunner().invoke(main, ["leaderboard", str(out), str(ev), "--sort", "pos_rmse", "-o", str(merged)])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(open(merged)))
    assert len(rows) == 5 and {r["filter"] for r in rows} == {"ekf", "ukf", "pf", "ckf"}
    vals = [float(r["pos_rmse"]) for r in rows]
    assert vals == sorted(vals)
    bad = CliRunner().invoke(main, ["leaderboard", str(out), "--sort", "nonsense"])
    assert bad.exit_code == 2 and "--sort nonsense" in bad.output


def test_paired_and_consistency_columns(serial):
    out = serial[0]
    rows = {r["label"]: r for r in board_rows(out)}
    ukf = rows["ukf(alpha=0.5)"]
    lo, hi = float(ukf["anees_lo"]), float(ukf["anees_hi"])
    from replay.scoring.metrics import chi2_band

    one_lo, one_hi = chi2_band(3, 6)  # the band of one step's average over the 6 runs
    assert one_lo < lo < 3 < hi < one_hi  # the band of the mean over runs and steps: narrower
    assert 0 <= float(ukf["anees_inside"]) <= 1 and float(ukf["anis"]) > 0
    assert rows["pf"]["anis"] == "nan"  # the PF has no innovation covariance
    paired = list(csv.DictReader(open(out / "paired.csv")))
    assert len(paired) == 6 * 2 and all(p["n"] == "6" for p in paired)


def test_extended_campaign_computes_only_the_new_filters(serial, tmp_path):
    only_ekf = SMALL.split("[[filter]]")[0] + '[[filter]]\nname = "ekf"\n'
    out = tmp_path / "out"
    assert execute.run(spec.load(write(tmp_path, only_ekf, "a.toml")), out, execute.RunOptions(workers=1, quiet=True))["units"] == 6
    more = execute.run(spec.load(write(tmp_path, SMALL, "b.toml")), out, execute.RunOptions(workers=1, quiet=True))
    assert more["units"] == 18 and more["stored_before"] == 6
    assert board_rows(out) == board_rows(serial[0])


def _unit(run, n=4):
    return RunRecord(run, "done", {"diverged": False},
                     {"k": np.arange(n), "t": np.arange(n) * 0.5, "nees": np.ones(n), "nis": np.ones(n),
                      "nis_dof": np.full(n, 2)})


def test_store_flushes_each_record_and_the_directory_once_per_job(tmp_path, monkeypatch):
    """Durability: each record is fsynced before its rename, then the directory once per job
    (tables are vouched for by the checksum in their record)."""
    from replay.campaign import store as store_mod

    synced = []
    real = os.fsync
    monkeypatch.setattr(store_mod.os, "fsync", lambda fd: (synced.append(os.readlink(f"/proc/self/fd/{fd}")),
                                                           real(fd))[1])
    s = store_mod.Store(tmp_path)
    (s.units / "h").mkdir(parents=True)
    s.write_job("h", [_unit(0), _unit(1), RunRecord(2, "failed", error="X: y")])
    names = [os.path.basename(p) for p in synced]
    # the records in any order (written side by side by write_job's threads), then the directory
    assert sorted(names[:3]) == [f".{run}.json.{os.getpid()}.tmp" for run in (0, 1, 2)] and names[3:] == ["h"]
    assert s.stored_runs("h") == {0, 1, 2}


def test_records_without_a_table_description_are_checked_against_the_others(tmp_path):
    """Units stored before records described their table: still read, and a table of another
    row count than the configuration's other units is damaged."""
    from replay.campaign.store import Store

    s = Store(tmp_path)
    (s.units / "h").mkdir(parents=True)
    s.write_job("h", [_unit(0), _unit(1), _unit(2, n=3)])
    for run in (0, 1, 2):  # as written before: no "table" (nor checksum) in the record
        p = s.units / "h" / f"{run}.json"
        p.write_text(json.dumps({k: v for k, v in json.loads(p.read_text()).items()
                                 if k not in ("table", "record_sha256")}))
    good, bad = s.scan("h")
    assert sorted(good) == [0, 1] and list(bad) == [2]
    assert bad[2] == f"{s.units / 'h' / '2.parquet'}: 3 rows, the configuration's other units have 4"
    with pytest.raises(ReplayError, match=r"2\.parquet: 3 rows.*run `replay campaign run`"):
        s.records("h")


def test_second_campaign_waits_for_the_lock_with_wait(tmp_path):
    """--wait: the second process blocks until the first releases the directory's lock."""
    import threading

    from replay.campaign.lock import holder, locked

    order = []
    with locked(tmp_path) as path:
        assert holder(path) == str(os.getpid())
        with pytest.raises(ReplayError, match=rf"pid {os.getpid()}\) is writing to"):
            with locked(tmp_path):
                pass
        def second():
            with locked(tmp_path, wait=True):
                order.append("second")

        waiter = threading.Thread(target=second)
        waiter.start()
        waiter.join(0.3)
        order.append("first released")
    waiter.join(10)
    assert order == ["first released", "second"]


def test_plain_name_with_dots_and_dashes_is_accepted(tmp_path):
    """Only names that would leave runs/ are refused (tests/test_hostile_campaign.py)."""
    c = spec.load(write(tmp_path, SMALL.replace('name = "small"', 'name = "sweep.v2-a_b"')))
    assert c.name == "sweep.v2-a_b"
