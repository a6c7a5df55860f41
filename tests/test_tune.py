"""``replay tune`` (issue 25 item 3): recovery of known noise, determinism, resume, held-out = eval."""
import csv
import math
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli import main

SMALL = ["sim/linear", "--filters", "kf,ekf", "--split", "seeds", "--dataset-param", "steps=60",
         "-p", "task.q=log[0.01,10]", "-p", "task.r=log[0.1,20]", "--runs", "2", "-q"]


def tune(out, *extra, trials=6, args=SMALL):
    res = CliRunner().invoke(main, ["tune", *args, "--trials", str(trials), "--out", str(out), *extra])
    assert res.exit_code == 0, res.output
    return res


def board(out):
    with open(out / "leaderboard.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def tuned_run(tmp_path_factory):
    """One ``tune(out)`` (SMALL, 6 trials, seed 0) shared by the tests that only read it (read-only:
    a test that writes into it works on a copy): (its directory, what it printed)."""
    out = tmp_path_factory.mktemp("tune") / "a"
    return out, tune(out).output


@pytest.fixture(scope="module")
def tuned(tuned_run):
    return tuned_run[0]


# slow: a second whole tune (the quick check keeps test_local_pool_gives_the_serial_rows)
@pytest.mark.slow
def test_same_seed_twice_same_best_and_rows(tmp_path, tuned_run):
    (adir, a), b = tuned_run, tune(tmp_path / "b").output
    ra, rb = board(adir), board(tmp_path / "b")
    assert [r["label"] for r in ra] == ["kf (default)", "kf (tuned)", "ekf (default)", "ekf (tuned)",
                                        "measurements (raw observations)"]
    assert ra[-1]["train_score"] == "" and float(ra[-1]["test_score"]) == float(ra[-1]["pos_rmse"]) > 2
    assert ra == rb
    table = lambda out: "\n".join(ln for ln in out.splitlines() if not ln.startswith("replay: note:"))  # noqa: E731
    assert table(a).replace(f"{adir}/", f"{tmp_path / 'b'}/") == table(b)  # (a one-time compile note may precede)
    for f in ("tuned-kf.toml", "tuned-ekf.toml"):  # tuned to other task parameters: one file each
        assert (adir / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
    assert not (adir / "tuned.toml").exists()
    tuned = [r for r in ra if r["label"].endswith("(tuned)")]
    default = [r for r in ra if r["label"].endswith("(default)")]
    for t, d in zip(tuned, default):  # the defaults are trial 0: tuning never ends worse on training
        assert float(t["train_score"]) <= float(d["train_score"])
        assert t["trials"] == "6" and d["trials"] == "0"
        assert t["tuned_on"] == "sim/linear steps=60 (seed 0)" and t["tested_on"].endswith("(seed 1)")
        assert t["test_config_hashes"] != t["train_config_hashes"]
    c = tune(tmp_path / "c", "--seed", "3")  # another seed: other trials
    assert board(tmp_path / "c")[1]["params"] != ra[1]["params"]


@pytest.mark.slow
def test_resume_after_a_trial_left_running_gives_the_uninterrupted_result(tmp_path):
    """Slow: three tunes (10-25 s); the fast subset keeps tests/test_tune_study.py::
    test_a_damaged_study_is_refused_naming_the_file_then_recomputed_from_the_units (a tune resumed from
    its stored units gives the uninterrupted leaderboard, byte for byte)."""
    from replay.tune import study as studies

    tune(tmp_path / "whole", trials=5)  # 5 trials: the left-running one is the third
    part = tmp_path / "part"
    tune(part, trials=2)
    store = studies.storage(part)  # a kill between ask and tell: a RUNNING trial with its parameters
    import optuna

    st = optuna.load_study(study_name="kf", storage=store)
    from replay.tune.space import Dim

    dims = [Dim("task", "q", "log", 0.01, 10), Dim("task", "r", "log", 0.1, 20)]
    studies.next_trial(st, dims, 0, "kf")
    assert len(st.get_trials(states=(optuna.trial.TrialState.RUNNING,))) == 1
    tune(part, trials=5)
    assert board(part) == board(tmp_path / "whole")


@pytest.mark.slow
def test_kill_9_mid_way_then_resume_gives_the_uninterrupted_result(tmp_path):
    args = ["-m", "replay.cli", "tune", *SMALL, "--trials", "25"]
    whole = subprocess.run([sys.executable, *args, "--out", str(tmp_path / "whole")], capture_output=True, text=True)
    assert whole.returncode == 0, whole.stderr
    part = tmp_path / "part"
    proc = subprocess.Popen([sys.executable, *args, "--out", str(part)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    import optuna

    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        time.sleep(0.2)
        try:
            trials = optuna.load_study(study_name="kf", storage=f"sqlite:///{part / 'study.db'}").trials
        except Exception:  # noqa: BLE001 — not created yet
            continue
        if len([t for t in trials if t.state.name == "COMPLETE"]) >= 5:
            break
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (part / "leaderboard.csv").exists()
    again = subprocess.run([sys.executable, *args, "--out", str(part)], capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert board(part) == board(tmp_path / "whole")


@pytest.mark.slow
def test_eval_tuned_gives_the_held_out_row(tmp_path, tuned):
    """Slow: a tune's file through eval, rerun and a campaign in a subprocess (10-25 s); the fast subset
    keeps tests/test_tuned_views.py::test_eval_tuned_alone_gives_the_held_out_rows_exactly (replay eval
    --tuned gives the tune's held-out row exactly)."""
    from replay.campaign import board as cboard

    row = [r for r in board(tuned) if r["label"] == "kf (tuned)"][0]
    res = CliRunner().invoke(main, ["eval", "sim/linear", "--dataset-param", "steps=60", "--tuned",
                                    str(tuned / "tuned-kf.toml"), "--runs", "2", "--seed", "1", "-q",
                                    "--out", str(tmp_path / "e")])
    assert res.exit_code == 0, res.output
    import json

    ev = json.loads((tmp_path / "e" / "manifest.json").read_text())["results"]  # full precision
    assert set(ev) == {"kf", "measurements"}  # the file's filters
    assert ev["kf"]["config_hash"] == row["test_config_hashes"]
    held = {r["config_hash"]: r for r in cboard.campaign_rows(tuned)}[row["test_config_hashes"]]
    for col in ("pos_rmse", "pos_rmse_median", "x_rmse", "ate", "final_err", "nees", "nis", "anees", "scored"):
        assert float(ev["kf"][col]) == pytest.approx(float(held[col]), rel=1e-12, abs=0), col
    assert float(row["pos_rmse"]) == pytest.approx(float(ev["kf"]["pos_rmse"]), rel=1e-5)
    again = CliRunner().invoke(main, ["rerun", str(tmp_path / "e" / "manifest.json"), "-q"])
    assert again.exit_code == 0 and "reproduced" in again.output, again.output  # replay rerun repeats it
    camp = subprocess.run([sys.executable, "-m", "replay.cli", "campaign", "run", str(tuned / "tuned-kf.toml"),
                           "--out", str(tmp_path / "c"), "-q", "--workers", "1"], capture_output=True, text=True)
    assert camp.returncode == 0, camp.stderr  # a campaign file too
    assert row["test_config_hashes"] in {r["config_hash"] for r in cboard.campaign_rows(tmp_path / "c")}


def _nll(q, r, runs, steps, seed):
    from replay.run.pipeline import Config, run_block

    c = Config("sim/linear", {"steps": steps, "q": 0.3, "r": 2.0}, None, "linear",
               {"q": 1.0, "r": 1.0, "p0": 1.0, "lost_threshold": 20.0, "lost_steps": 10}, "kf",
               {"q_scale": q, "r_scale": r}, seed, "se3", None)
    return sum(rec.metrics["nll"] for rec in run_block(c.as_dict(), list(range(runs))))


@pytest.mark.slow
def test_nll_tune_recovers_the_true_q_and_r_within_their_sampling_error(tmp_path):
    """sim/linear with q = 0.3, r = 2 (per axis); the task's model assumes q = r = 1, and the
    Kalman filter's q_scale and r_scale are tuned on the innovations' likelihood over 8 runs x
    300 steps (60 trials). The sampling error of (log q, log r) is from the curvature of the
    summed nll at the tuned point (observed Fisher information)."""
    args = ["sim/linear", "--filters", "kf", "--split", "seeds", "--dataset-param", "steps=300",
            "-p", "kf.q_scale=log[0.01,10]", "-p", "kf.r_scale=log[0.1,20]", "--runs", "8", "--objective", "nll",
            "-q"]
    tune(tmp_path / "t", trials=60, args=args)
    rows = board(tmp_path / "t")
    row = [r for r in rows if r["label"] == "kf (tuned)"][0]
    import json

    p = json.loads(row["params"])
    q, r = p["q_scale"], p["r_scale"]
    h = 0.05  # in log space
    f = lambda a, b: _nll(q * math.exp(a), r * math.exp(b), 8, 300, 0)
    f0 = f(0, 0)
    hqq = (f(h, 0) - 2 * f0 + f(-h, 0)) / h ** 2
    hrr = (f(0, h) - 2 * f0 + f(0, -h)) / h ** 2
    hqr = (f(h, h) - f(h, -h) - f(-h, h) + f(-h, -h)) / (4 * h ** 2)
    cov = np.linalg.inv([[hqq, hqr], [hqr, hrr]])
    se_q, se_r = np.sqrt(np.diag(cov))
    zq, zr = (math.log(q / 0.3)) / se_q, (math.log(r / 2.0)) / se_r
    print(f"tuned q {q:.4f} (true 0.3, se {100 * se_q:.1f} %, z {zq:.2f}); r {r:.4f} (true 2, se "
          f"{100 * se_r:.1f} %, z {zr:.2f})")
    assert abs(zq) < 3 and abs(zr) < 3
    assert 0.03 < se_q < 0.25 and 0.01 < se_r < 0.1  # the test can fail: the errors are this tight
    default = [x for x in rows if x["label"] == "kf (default)"][0]
    assert float(row["test_score"]) < float(default["test_score"])


def test_report_of_a_tune_directory(tmp_path, tuned):
    shutil.copytree(tuned, tmp_path / "t")  # the report is written into the directory
    res = CliRunner().invoke(main, ["report", str(tmp_path / "t")])
    assert res.exit_code == 0, res.output
    rep = tmp_path / "t" / "report"
    assert {p.name for p in rep.iterdir()} >= {"report.html", "history_kf.png", "history_ekf.png",
                                               "importance_kf.png", "importance_ekf.png"}
    page = (rep / "report.html").read_text()
    assert "Train versus test" in page and "kf (tuned)" in page and page.count("<img") == 4


def test_campaign_tune_table_shares_one_store_and_gives_the_tune_rows(tmp_path, tuned):
    """A campaign's [tune] table runs the tune of each dataset x task with the campaign's runs and
    seed: the same rows as `replay tune` with those options; its units in OUT/tune/units."""
    camp = tmp_path / "c.toml"
    camp.write_text('[campaign]\nruns = 2\nseed = 0\n[[dataset]]\nid = "sim/linear"\nparams = { steps = 60 }\n'
                    '[[filter]]\nname = "kf"\n[[filter]]\nname = "ekf"\n'
                    '[tune]\ntrials = 6\nsplit = { seeds = 0 }\n'
                    'space = { "task.q" = "log[0.01,10]", "task.r" = "log[0.1,20]" }\n')
    res = CliRunner().invoke(main, ["campaign", "run", str(camp), "--out", str(tmp_path / "o"), "-q", "--workers", "1"])
    assert res.exit_code == 0, res.output
    tuned_dir = tmp_path / "o" / "tune" / "sim_linear_linear"
    assert (tmp_path / "o" / "tune" / "units").is_dir() and not (tuned_dir / "units").exists()
    # `tuned`: replay tune with the same data, runs, seed, space and trials
    strip = lambda rows: [{k: v for k, v in r.items() if k not in ("tuned_on", "tested_on")} for r in rows]
    assert strip(board(tuned_dir)) == strip(board(tuned))
    bad = tmp_path / "bad.toml"
    bad.write_text(camp.read_text().replace("trials = 6", "trials = 6\nbudget = 3"))
    res = CliRunner().invoke(main, ["campaign", "run", str(bad), "--out", str(tmp_path / "b"), "-q"])
    assert res.exit_code == 2 and "bad.toml:" in res.output and "[tune]: budget: unknown key" in res.output
    assert not (tmp_path / "b").exists()  # before any unit
    bad.write_text(camp.read_text().replace('"task.q" = "log[0.01,10]"', '"task.q" = "log[0,10]"'))
    res = CliRunner().invoke(main, ["campaign", "run", str(bad), "--out", str(tmp_path / "b"), "-q"])
    assert res.exit_code == 2 and "a log range needs positive bounds" in res.output and not (tmp_path / "b").exists()


def test_local_pool_gives_the_serial_rows(tmp_path, tuned):
    """A trial's runs spread over the workers (one run per job here), with the serial numbers."""
    from replay.campaign.execute import spread_block

    assert [spread_block(2, 25, 2, None), spread_block(5, 25, 2, None), spread_block(5, 2, 2, None)] == [1, 3, 2]
    assert spread_block(5, 25, 1, None) == 5 and spread_block(5, 25, None, "tcp://x:8786") == 2  # a remote scheduler: 4 workers
    tune(tmp_path / "pool", "--workers", "2")  # each trial's 2 runs in 2 processes; `tuned`: serial
    assert board(tmp_path / "pool") == board(tuned)


@pytest.mark.parametrize("fparams", [{}, {"q_scale": 0.3, "r_scale": 2.0}])
def test_nll_is_the_textbook_kalman_likelihood(fparams):
    """The recorded nll against an independent Kalman filter's innovation likelihood (numpy loop),
    with the task's noise and under the filter's own noise settings."""
    from replay.run.pipeline import build_problem, run_block

    cfg = {"dataset": "sim/linear", "dataset_params": {"steps": 40, "q": 0.3, "r": 2.0}, "first": None,
           "task": "linear", "task_params": {"q": 1.0, "r": 1.0, "p0": 1.0, "lost_threshold": 20.0, "lost_steps": 10},
           "filter": "kf", "filter_params": fparams, "seed": 4, "alignment": "se3", "divergence_threshold": None}
    rec = run_block(cfg, [0])[0]
    p = build_problem(cfg, 0)
    q, r = fparams.get("q_scale", 1.0), fparams.get("r_scale", 1.0)
    x, P, total = np.asarray(p.x0, float), np.asarray(p.P0, float), 0.0
    for z in p.z:
        P = P + q * np.eye(3)
        S = P + r * np.eye(3)
        y = z - x
        total += 0.5 * (y @ np.linalg.solve(S, y) + np.linalg.slogdet(S)[1] + 3 * math.log(2 * math.pi))
        K = P @ np.linalg.inv(S)
        x, P = x + K @ y, (np.eye(3) - K) @ P
    assert rec.metrics["nll"] == pytest.approx(total, rel=1e-10)
    rec_pf = run_block({**cfg, "filter": "pf", "filter_params": {"n_particles": 50}}, [0])[0]
    assert "nll" not in rec_pf.metrics  # a particle filter gives none
