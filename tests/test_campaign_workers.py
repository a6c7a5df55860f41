"""Local pool workers end when `replay campaign run` is killed with SIGKILL."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

LONG = """\
[campaign]
runs = 400
batch = 1
[[dataset]]
id = "sim/auv-sonar"
[[filter]]
name = "pf"
params = { n_particles = 3000 }
"""


def children(pid: int) -> list[int]:
    """Live (not zombie) processes whose parent is ``pid``, from /proc."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            state, ppid = stat.rsplit(")", 1)[1].split()[:2]
            if int(ppid) == pid and state != "Z":
                out.append(int(d.name))
    return out


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc to find the workers")
@pytest.mark.slow
def test_workers_exit_when_campaign_is_killed(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(LONG)
    cmd = [sys.executable, "-m", "replay.cli", "campaign", "run", str(path), "-o", str(tmp_path / "out"),
           "-w", "2", "-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline, workers = time.monotonic() + 60, []
        while time.monotonic() < deadline and len(workers) < 2:
            assert proc.poll() is None, "the campaign ended before its workers started"
            time.sleep(0.1)
            workers = children(proc.pid)
        assert len(workers) >= 2, workers
        time.sleep(0.5)  # the workers are computing units
        assert all(alive(w) for w in workers)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and any(alive(w) for w in workers):
            time.sleep(0.05)
        survivors = [w for w in workers if alive(w)]
        assert not survivors, f"orphaned workers still running: {survivors}"
    finally:
        for w in children(proc.pid) + [proc.pid]:
            try:
                os.kill(w, signal.SIGKILL)
            except OSError:
                pass
        proc.wait()


def test_watch_thread_fallback_ends_an_orphan(tmp_path):
    """Without prctl: the getppid watch alone ends a worker whose parent died."""
    code = ("import os, sys, time\n"
            "from replay.campaign import workers\n"
            "workers._pdeathsig = lambda sig: False\n"
            "pid = os.fork()\n"
            "if pid == 0:\n"
            "    workers.init_worker(os.getppid(), poll=0.05)\n"
            "    time.sleep(60)\n"
            "    os._exit(0)\n"
            "print(pid, flush=True)\n"
            "time.sleep(0.5)\n"
            "os._exit(0)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    child = int(res.stdout.split()[0])
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and alive(child):
        time.sleep(0.05)
    assert not alive(child)


def test_worker_blas_limit():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import numpy  # noqa: F401  (loads OpenBLAS, as in a forked worker)

    from replay.campaign import workers

    workers.limit_threads(1)
    try:
        blas = [p for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"]
        assert blas and all(p["num_threads"] == 1 for p in blas)
    finally:
        workers._limits.restore_original_limits()


def test_packed_results_store_the_same_table(tmp_path):
    """Parquet encoded in the worker (pack) and in the main process give the same stored table."""
    import numpy as np

    from replay.campaign.store import Store, pack
    from replay.scoring.record import RunRecord

    series = {"k": np.arange(5), "t": np.linspace(0, 1, 5), "nees": np.array([1.0, np.nan, 2.0, 3.0, 4.0])}
    res = [RunRecord(0, "done", {"rmse": 1.5}, series), RunRecord(1, "failed", error="X: y")]
    packed = pack(res)
    assert packed[0].series is None and packed[0].parquet[:4] == b"PAR1" and packed[1] == res[1]
    assert list(packed[0].leaderboard_columns) == ["nees"] and res[0].series is series  # the input untouched
    a, b = Store(tmp_path / "a"), Store(tmp_path / "b")
    for store, results in ((a, res), (b, packed)):
        (store.units / "h").mkdir(parents=True)
        for r in results:
            store.write("h", r)
    for name in ("k", "t", "nees"):
        np.testing.assert_array_equal(a.series("h", 0)[name], b.series("h", 0)[name])
    assert a.records("h") == b.records("h") and a.stored_runs("h") == {0, 1}


def test_unit_tables_do_not_import_pandas(tmp_path):
    """Writing and reading a unit's table stays clear of pandas (about 1 s to import, per process)."""
    code = ("import sys, numpy as np\n"
            "from replay.campaign.store import Store, pack\n"
            "from replay.scoring.record import RunRecord\n"
            "s = Store(sys.argv[1]); (s.units / 'h').mkdir(parents=True)\n"
            "r = pack([RunRecord(0, 'done', {}, {'k': np.arange(4), "
            "'nees': np.array([1.0, np.nan, 2.0, 3.5])})])[0]\n"
            "s.write('h', r)\n"
            "t = s.series('h', 0)\n"
            "assert t['k'].dtype == np.int64 and t['k'].tolist() == [0, 1, 2, 3], t\n"
            "assert np.array_equal(t['nees'], [1.0, np.nan, 2.0, 3.5], equal_nan=True)\n"
            "print('pandas' in sys.modules)\n")
    res = subprocess.run([sys.executable, "-c", code, str(tmp_path / "o")], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"


def _silent_listener():
    """A socket that accepts connections and never answers (the kernel completes the TCP handshake)."""
    import socket

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(8)
    return sock


@pytest.mark.slow  # waits out deadlines (over 1 s): the full suite runs it
def test_scheduler_that_accepts_and_never_answers_is_refused_in_time():
    """A fake scheduler that accepts the connection and sends nothing: one line naming the
    address and the timeout (before: `campaign run` hung for ever in the Dask handshake)."""
    pytest.importorskip("distributed")
    from replay.campaign.workers import connect_scheduler
    from replay.util.errors import ReplayError

    with _silent_listener() as sock:
        address = f"tcp://127.0.0.1:{sock.getsockname()[1]}"
        with pytest.raises(ReplayError) as err:
            connect_scheduler(address, 1)
    assert str(err.value) == (f"Dask scheduler {address}: no answer within 1 s "
                              "(it accepted the connection but sent no handshake)")


def test_scheduler_address_errors_are_one_line():
    pytest.importorskip("distributed")
    from replay.campaign.workers import connect_scheduler
    from replay.util.errors import ReplayError

    with pytest.raises(ReplayError, match=r"^Dask scheduler nope://x: not a scheduler address \(unknown address "
                                          r"scheme 'nope'"):
        connect_scheduler("nope://x", 1)
    with _silent_listener() as sock:
        port = sock.getsockname()[1]
        sock.close()  # nothing listens there now
        with pytest.raises(ReplayError, match=rf"^Dask scheduler tcp://127.0.0.1:{port}: no answer within 0.5 s "
                                              r"\(nothing accepted the connection\)$"):
            connect_scheduler(f"tcp://127.0.0.1:{port}", 0.5)


@pytest.mark.slow
def test_campaign_run_with_a_silent_scheduler_ends(tmp_path):
    """`replay campaign run --scheduler` against a scheduler that never answers ends with one
    line within seconds (needs replay/campaign/execute.py to connect through connect_scheduler)."""
    pytest.importorskip("distributed")
    path = tmp_path / "c.toml"
    path.write_text(LONG.replace("runs = 400", "runs = 2"))
    with _silent_listener() as sock:
        address = f"tcp://127.0.0.1:{sock.getsockname()[1]}"
        cmd = [sys.executable, "-m", "replay.cli", "campaign", "run", str(path), "-o", str(tmp_path / "out"),
               "--scheduler", address, "-q"]
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        except subprocess.TimeoutExpired:
            pytest.fail("campaign run still waiting for the scheduler after 60 s")
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [f"replay: error: Dask scheduler {address}: no answer within 5 s "
                                               "(it accepted the connection but sent no handshake)"]




_PARENT, _ORIGINAL, _HERE = os.getpid(), [], []


def _where(job):  # (whether the job ran in the test's process, its kernel threads), its records
    here = (os.getpid() == _PARENT, os.environ.get("REPLAY_THREADS"))
    if here[0]:
        _HERE.append((job.config_hash, here[1]))  # seen only when run in this process
    return here, _ORIGINAL[0](job)


@pytest.mark.skipif(sys.platform != "linux", reason="the warm-first pool is forked (Linux)")
@pytest.mark.slow
def test_warm_jobs_run_here_with_the_workers_threads_before_the_pool_forks(monkeypatch):
    """``replay tune``'s pool: its warm jobs (a short run of each filter) run in this process with the
    workers' thread count, before the workers are forked (they start with those kernels compiled);
    every job given to the pool runs in a worker, and the records equal those of the serial backend."""
    from replay.campaign import execute
    from replay.campaign.units import Job
    from replay.campaign.workers import worker_threads
    from replay.run.pipeline import Config

    def job(name, runs, first=None, label=None):
        c = Config("sim/auv-sonar", {"steps": 20}, first, "sonar", {}, name, {}, 0, "se3", None).as_dict()
        return Job(c, label or name, runs)

    def numbers(records):  # all but the timings
        return [(r.run, r.status, {k: v for k, v in r.metrics.items() if k not in ("us_per_step", "seconds")})
                for r in records]

    jobs = [job("ekf", [r]) for r in range(3)] + [job("kf", [r]) for r in range(2)]
    serial = {(j.config_hash, j.runs[0]): numbers(res) for j, res in execute._serial(jobs)}
    _ORIGINAL.append(execute.execute_packed)
    monkeypatch.setattr(execute, "execute_packed", _where)
    warm = [job("ekf", [0], 5, "ekf-warm"), job("kf", [0], 5, "kf-warm")]
    got = {}
    try:
        before = os.environ.get("REPLAY_THREADS")
        with execute._processes(2, warm=warm) as run:
            for name in ("ekf", "kf"):
                for j, ((here, threads), recs) in run([j for j in jobs if j.config_hash == name]):
                    assert not here and threads == str(worker_threads(2))  # in a worker
                    got[j.config_hash, j.runs[0]] = numbers(recs)
        assert os.environ.get("REPLAY_THREADS") == before  # this process's own setting again
        assert _HERE == [("ekf-warm", str(worker_threads(2))), ("kf-warm", str(worker_threads(2)))]
    finally:
        _ORIGINAL.clear()
        _HERE.clear()
    assert got == serial and len(got) == 5
