"""Progress: a bar on a terminal (driven under a pseudo-terminal), periodic lines otherwise, silence
with -q; the ETA weights work by its expected cost."""
import io
import os
import pty
import subprocess
import sys

import pytest

from replay.util.progress import Progress, particle_weight


def test_eta_weights_items_by_cost():
    p = Progress(3, stream=io.StringIO(), total_weight=100.0, every=1e9)
    p.t0 -= 10.0                      # 10 s elapsed
    p.update(2, weight=20.0)          # two cheap items done: 20 % of the work
    assert p.eta(p.t0 + 10.0) == pytest.approx(40.0)  # 10 s per 20 -> 40 s for the 80 left, not 5 s
    assert particle_weight({"n_particles": 1000}, 10) == 500 and particle_weight({}, 10) == 10
    assert particle_weight({"n_particles": 100, "t_max": 20}, 1) == 100


def test_plain_lines_when_not_a_terminal_and_nothing_when_quiet():
    out = io.StringIO()
    p = Progress(2, stream=out, label="eval", unit="run", every=0.0)
    p.update(1)
    p.update(1)
    assert out.getvalue().splitlines()[-1].startswith("eval: 2/2 runs (100 % of the work)")
    q = io.StringIO()
    p = Progress(2, quiet=True, stream=q, every=0.0)
    p.update(2)
    assert q.getvalue() == ""


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
