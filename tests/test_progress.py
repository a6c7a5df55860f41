"""Progress: a bar on a terminal (driven under a pseudo-terminal), periodic lines otherwise, silence
with -q; the ETA weights work by its expected cost."""
import io
import os
import pty
import subprocess
import sys

import pytest

from replay.util.errors import ReplayError
from replay.util.progress import Progress, particle_weight


def test_eta_weights_items_by_cost_and_leaves_out_the_first_item():
    p = Progress(4, stream=io.StringIO(), total_weight=100.0, every=1e9)
    p.update(1, weight=5.0)           # the first item: it carries the one-time work (no rate yet)
    assert p.eta() != p.eta()         # NaN: no ETA from the first item alone (issue 40: 74x too long)
    t1 = p.first[0]
    p.update(2, weight=20.0)          # two cheap items since: 20 of the work in 10 s
    assert p.eta(t1 + 10.0) == pytest.approx(37.5)  # 10 s per 20 -> 37.5 s for the 75 left, not 5 s
    # per run: 4 (the work besides the filter) + particles / 20 x iterations
    assert particle_weight({"n_particles": 1000}, 10) == 540 and particle_weight({}, 10) == 50
    assert particle_weight({"n_particles": 100, "t_max": 20}, 1) == 104


def test_the_count_never_passes_its_total():
    out = io.StringIO()
    p = Progress(11, stream=out, label="eval", unit="run", every=0.0)
    p.update(20)  # a caller's overshoot (issue 40: "20/11 runs (182 %)") is not shown
    assert out.getvalue().startswith("eval: 11/11 runs (100 % of the work)")


def test_eval_with_a_recorded_estimate_counts_its_one_run(tmp_path):
    """A recorded estimate is one run: an eval of 5 runs with one filter and one recorded estimate
    counts 5 + 1 (it counted 5 + 5 and passed its total)."""
    import numpy as np

    import replay
    from replay.sim.auv_bag import make_bag

    make_bag(tmp_path / "bag", np.random.default_rng(0), duration=20.0)
    (tmp_path / "m.toml").write_text(
        'time = "header"\n[channels]\ndvl = { topic = "/dvl/twist", type = '
        '"geometry_msgs/msg/TwistWithCovarianceStamped" }\n'
        'imu = { topic = "/imu/data", type = "sensor_msgs/msg/Imu", fuse = ["gyro"] }\n[reference]\nposition = { topic = "/reference/pose", '
        'type = "geometry_msgs/msg/PoseStamped" }\n[estimates]\ntruth = { topic = "/reference/pose", '
        'type = "geometry_msgs/msg/PoseStamped" }\n'
    )
    counts = []

    class Counting(Progress):
        def update(self, n=1, failed=0, weight=None):
            super().update(n, failed, weight)
            counts.append((self.done, self.items, self.weight_done, self.total_weight))  # items: the count

    ev = replay.evaluate(str(tmp_path / "bag"), filters=["ekf"], runs=5, recorded=None,
                         dataset_params={"mapping": str(tmp_path / "m.toml")}, progress=Counting(0, stream=io.StringIO()))
    assert [r.name for r in ev.results] == ["ekf", "recorded:truth"]
    assert [c[:2] for c in counts] == [(5, 6), (6, 6)]  # 5 runs of ekf, then the recording's one
    assert counts[-1][2] == pytest.approx(counts[-1][3])  # the weight done is the whole weight


def test_plain_lines_when_not_a_terminal_and_nothing_when_quiet():
    out = io.StringIO()
    p = Progress(2, stream=out, label="eval", unit="run", every=0.0)
    p.update(1)
    p.update(1)
    assert out.getvalue().splitlines()[-1].startswith("eval: 2/2 runs (100 % of the work)")
    q = io.StringIO()
    p = Progress(2, quiet=True, stream=q, every=0.0, total_weight=10.0)
    p.update(2, weight=10.0)
    assert q.getvalue() == "" and p.done == 2 and p.weight_done == 10.0  # quiet: counted all the same


def _in_pty(args, cwd):
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "replay.cli", *args], stdin=slave, stdout=slave, stderr=slave,
                            cwd=cwd, close_fds=True)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:  # the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    proc.wait(timeout=300)
    os.close(master)
    return proc.returncode, b"".join(chunks).decode(errors="replace")


@pytest.mark.slow
def test_eval_shows_a_bar_on_a_terminal_and_nothing_with_q(tmp_path):
    args = ["eval", "sim/ungm", "--task", "ungm", "-f", "ekf,pf", "--runs", "30", "-p", "pf.n_particles=200"]
    rc, text = _in_pty([*args, "-o", "a"], tmp_path)
    assert rc == 0, text
    assert "eval: 100%|####" in text and "60/60 runs" in text  # the bar, weighted, with counts
    rc, text = _in_pty([*args, "-o", "b", "-q"], tmp_path)
    assert rc == 0 and "eval:" not in text and "%|" not in text and "pos_rmse" in text


def test_export_counts_every_message_it_writes(tmp_path):
    """The MCAP and ROS 2 bag writers announce their total before writing and report each message
    once: the last line says N/N with N the number of messages the writer returns."""
    from test_export_mcap import synthetic_run

    from replay.outputs.export_mcap import write_mcap
    from replay.outputs.export_ros2 import write_run_ros2

    frame, problem, est = synthetic_run(n=800)
    out = io.StringIO()
    p = Progress(0, stream=out, label="export mcap", unit="message", every=1e9)
    n = write_mcap(tmp_path / "r.mcap", frame, problem, est, window=2000, progress=p)
    assert p.total == p.done == n > 800
    lines = out.getvalue().splitlines()  # one line: the end (the next is due in 1e9 s)
    assert len(lines) == 1 and lines[0].startswith(f"export mcap: {n}/{n} messages (100 % of the work)")
    out = io.StringIO()
    p = Progress(0, stream=out, label="export ros2 bag", unit="message", every=1e9)
    n = write_run_ros2({"frame": frame, "problem": problem, "estimates": est}, tmp_path / "bag", progress=p)
    assert p.total == p.done == n and out.getvalue().startswith(f"export ros2 bag: {n}/{n} messages")
    q = io.StringIO()
    n = write_mcap(tmp_path / "q.mcap", frame, problem, est, progress=Progress(0, quiet=True, stream=q))
    assert n > 800 and q.getvalue() == ""


def test_export_progress_stays_short_when_the_file_cannot_be_finished(tmp_path, monkeypatch):
    """A write that fails at the end (a full disk when the last chunk is flushed) never says N/N."""
    from test_export_mcap import synthetic_run

    from replay.adapters.bags.writer import BagOut
    from replay.outputs import mcap_bulk
    from replay.outputs.export_mcap import write_mcap
    from replay.outputs.export_ros2 import write_run_ros2

    def full(*_a, **_k):
        raise OSError(28, "No space left on device")

    frame, problem, est = synthetic_run(n=800)
    monkeypatch.setattr(mcap_bulk.BulkWriter, "finish", full)
    out = io.StringIO()
    p = Progress(0, stream=out, label="export mcap", unit="message", every=1e9)
    with pytest.raises(ReplayError, match="No space left on device"):
        write_mcap(tmp_path / "r.mcap", frame, problem, est, window=500, progress=p)
    assert 0 < p.done < p.total and out.getvalue() == ""
    monkeypatch.setattr(BagOut, "close", full)
    p = Progress(0, stream=out, label="export ros2 bag", unit="message", every=1e9)
    with pytest.raises(ReplayError, match="No space left on device"):
        write_run_ros2({"frame": frame, "problem": problem, "estimates": est}, tmp_path / "bag", progress=p)
    assert p.done < p.total and out.getvalue() == ""


@pytest.mark.slow
def test_rerun_and_export_show_a_bar_on_a_terminal_and_nothing_with_q(tmp_path):
    args = ["eval", "sim/auv-sonar", "-f", "ekf,pf", "--runs", "3", "-p", "pf.n_particles=50", "-o", "run", "-q"]
    done = subprocess.run([sys.executable, "-m", "replay.cli", *args], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    rc, text = _in_pty(["rerun", "run/manifest.json"], tmp_path)
    assert rc == 0, text
    assert "rerun: 100%|####" in text and "6/6 runs" in text and "reproduced: every recorded result" in text
    rc, text = _in_pty(["rerun", "run/manifest.json", "-q"], tmp_path)
    assert rc == 0 and "rerun:" not in text and "%|" not in text and "reproduced: every recorded result" in text
    rc, text = _in_pty(["export", "run", "--mcap", "a.mcap", "--ros2-bag", "a_bag"], tmp_path)
    assert rc == 0, text
    n_mcap = int(text.split("wrote a.mcap (")[1].split()[0])
    n_bag = int(text.split("wrote a_bag/ (")[1].split()[0])
    assert n_mcap > n_bag > 0
    assert "export mcap: 100%|####" in text and f"{n_mcap}/{n_mcap} messages" in text
    assert "export ros2 bag: 100%|####" in text and f"{n_bag}/{n_bag} messages" in text
    rc, text = _in_pty(["export", "run", "--mcap", "a.mcap", "--ros2-bag", "a_bag", "-q"], tmp_path)
    assert rc == 0 and f"wrote a.mcap ({n_mcap} messages" in text and f"wrote a_bag/ ({n_bag} messages" in text
    assert "%|" not in text and "export mcap" not in text and "export ros2" not in text


def test_eta_leaves_out_the_time_spent_compiling_kernels(monkeypatch):
    """The issue's case: a first run's ETA (1243 s for a run of 80 s) extrapolated the one-time
    compilation of its kernels. 80 s since the first item, of which 70 compiling, 10 % of the work done."""
    from replay.util import progress

    monkeypatch.setitem(progress._CLOCK, "total", 5.0)  # compiled before this progress: not counted
    monkeypatch.setitem(progress._CLOCK, "depth", 0)
    out = io.StringIO()
    p = Progress(10, stream=out, total_weight=100.0, every=0.0, label="eval", unit="run")
    p.update(1, weight=10.0)  # the first item (left out of the rate)
    p.start_t -= 80.0  # tqdm's clock: the elapsed time shown
    p.first = (p.first[0] - 80.0, *p.first[1:])  # 80 s since the first item, 70 of them compiling
    progress._CLOCK["total"] += 70.0
    p.update(1, weight=10.0)
    assert p.eta(p.first[0] + 80.0) == pytest.approx(80.0)  # (80 - 70) s per 10 -> 80 s for the 80 left, not 640
    assert out.getvalue().rstrip().endswith("elapsed 80 s, 70 s compiling kernels, ETA 80 s")
    monkeypatch.setitem(progress._CLOCK, "depth", 1)  # compiling now (for 10 s): the ETA does not grow
    monkeypatch.setitem(progress._CLOCK, "start", p.first[0] + 80.0)
    assert p.eta(p.first[0] + 90.0) == pytest.approx(80.0)
    tty = _Tty()
    bar = Progress(10, stream=tty, total_weight=100.0)
    bar.update(1, weight=10.0)
    assert "progress:  10%|#" in tty.getvalue() and "1/10 units" in tty.getvalue()  # tqdm's bar, the count
    bar.close()


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_numba_compilations_are_timed_and_notes_erase_the_bar():
    import logging

    import numba as nb

    from replay.util import progress

    progress._listen()
    before = progress.compile_seconds()

    @nb.njit
    def fresh(x):  # compiled at its first call below (not cached)
        return x * 3.0 + 1.0

    assert fresh(2.0) == 7.0
    assert progress.compile_seconds() > before and progress._CLOCK["depth"] == 0
    tty = _Tty()
    bar = Progress(4, stream=tty)
    bar.update(1)
    h = progress.NoteHandler(tty)
    h.emit(logging.LogRecord("replay", logging.INFO, __file__, 1, "a note", None, None))
    text = tty.getvalue()
    before, after = text.split("a note\n")
    assert "1/4 units" in before and before.endswith(" \r")  # tqdm erased the bar: the note on its own line
    assert after.startswith("\r") and "1/4 units" in after  # and drew the bar again below it
    bar.close()
    assert tty.getvalue().endswith("\n")


def test_every_display_is_tqdm_s_and_off_a_terminal_each_is_a_plain_line():
    """The bar, the plain lines and the load heartbeat are tqdm instances (tqdm draws each), and off
    a terminal a display is a line of its own: no carriage return, no padding."""
    import tqdm

    from replay.util import progress

    out = io.StringIO()
    p = Progress(3, stream=out, label="eval", unit="run", every=0.0)
    p.update(1)
    assert isinstance(p, tqdm.tqdm) and p in tqdm.tqdm._instances
    p.update(2)
    p.close()
    lines = out.getvalue().split("\n")
    assert lines[0].startswith("eval: 1/3 runs (33 % of the work), elapsed 0 s") and lines[-1] == ""
    assert lines[1].startswith("eval: 3/3 runs (100 % of the work), elapsed 0 s") and len(lines) == 3
    assert "\r" not in out.getvalue() and p not in tqdm.tqdm._instances
    tty = _Tty()
    with progress.Loading("f.csv", 2000, quiet=False, stream=tty, after=0.0, every=0.01) as ld:
        import time
        deadline = time.monotonic() + 5
        while not tty.getvalue() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert isinstance(ld, tqdm.tqdm)
    assert tty.getvalue().startswith("\rload f.csv (2.00kB): 0 s") and tty.getvalue().endswith("done in 0 s\n")


def test_a_load_heartbeat_under_a_run_bar_off_a_terminal_writes_no_control_sequence():
    """Two displays at once off a terminal (a file's load heartbeat while a run's bar is open): tqdm
    moves the cursor between them (ESC [A); a log must get plain lines only. CI once saw an error
    line preceded by a line holding only ESC [A."""
    import time

    from replay.util import progress

    out = io.StringIO()
    bar = Progress(2, stream=out, label="eval", unit="run", every=0.0)
    bar.update(1)
    with progress.Loading("f.csv", 2000, quiet=False, stream=out, after=0.0, every=0.01):
        deadline = time.monotonic() + 5
        while "load f.csv" not in out.getvalue() and time.monotonic() < deadline:
            time.sleep(0.01)
    bar.update(1)
    bar.close()
    text = out.getvalue()
    assert "load f.csv (2.00kB): 0 s" in text and "done in 0 s" in text and "eval: 2/2 runs" in text
    assert "\x1b" not in text and "\r" not in text
    assert all(line.strip() for line in text.splitlines())  # no empty line either
