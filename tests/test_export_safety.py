"""Faults during an export leave the old output or none, never a part of one.

Each fault runs `replay export` in a child process that dies by SIGKILL at a chosen
point (the export code itself is not changed for the test: the child patches one
function before calling the CLI) or that hits the file-size limit (RLIMIT_FSIZE, as a
full disk would). Afterwards the target holds the complete old export (or nothing),
and the next export removes the hidden temporary the dead one left.
"""
import hashlib
import os
import resource
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from hostile import assert_ok, assert_refused

from replay.outputs.export_safety import export_set
from replay.util.staging import exchange, publish_dir


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("safety")
    assert_ok(["eval", "sim/auv-bag", "-f", "ekf", "--first", "300", "-o", root / "run"])
    return root / "run"


@pytest.fixture(scope="module")
def plain_run(tmp_path_factory):
    """A run whose dataset is generated in memory (sim/auv-bag writes a temporary bag itself)."""
    root = tmp_path_factory.mktemp("plain")
    assert_ok(["eval", "sim/lake-depth", "-f", "ekf", "--first", "300", "-o", root / "run"])
    return root / "run"


def digest(path: Path) -> str:
    h = hashlib.sha256()
    for p in sorted([path] if path.is_file() else path.rglob("*")):
        h.update(p.name.encode() + (p.read_bytes() if p.is_file() else b""))
    return h.hexdigest()


def hidden(target: Path) -> list[str]:
    return sorted(p.name for p in target.parent.iterdir() if p.name.startswith(f".{target.name}.staging-"))


def child(patch: str, args, limit=None) -> subprocess.CompletedProcess:
    """`replay ARGS` in a new Python process after running ``patch`` (which may kill it)."""
    code = textwrap.dedent(patch) + textwrap.dedent("""
        from replay.cli import main
        main(sys.argv[1:], prog_name="replay")
    """)

    def limits():
        if limit:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    return subprocess.run([sys.executable, "-c", "import os, sys, signal\n" + code, *map(str, args)],
                          capture_output=True, text=True, preexec_fn=limits, timeout=300)


KILL_IN_CHUNK = """
    from replay.outputs import mcap_bulk
    mcap_bulk.BulkWriter._close_chunk = lambda self: os.kill(os.getpid(), signal.SIGKILL)
"""
KILL_IN_BAG = """
    from replay.adapters.bags import writer
    write = writer.BagOut.write
    def dying(self, *a):
        if self.count == 50 and ".staging-" in str(self.path):  # the export, not the sim's own bag
            os.kill(os.getpid(), signal.SIGKILL)
        write(self, *a)
    writer.BagOut.write = dying
"""
KILL_BETWEEN_RENAMES = """
    from replay.util import staging
    staging.exchange = lambda a, b: False  # as on a file system without RENAME_EXCHANGE
    rename = os.rename
    def dying(a, b):
        if ".staging-" in str(a):  # the second rename: the new bag into place
            os.kill(os.getpid(), signal.SIGKILL)
        rename(a, b)
    os.rename = dying
"""


@pytest.mark.slow
@pytest.mark.parametrize("old", [True, False])
def test_kill_during_mcap_export_leaves_old_or_none(run, tmp_path, old):
    target = tmp_path / "r.mcap"
    if old:
        assert_ok(["export", run, "--mcap", target])
        before = digest(target)
    res = child(KILL_IN_CHUNK, ["export", run, "--mcap", target])
    assert res.returncode == -signal.SIGKILL
    assert (digest(target) == before) if old else not target.exists()
    assert len(hidden(target)) == 1  # the dead export's partial file, under a hidden name
    assert_ok(["export", run, "--mcap", target])
    assert hidden(target) == [] and target.stat().st_size > 10_000


@pytest.mark.slow
def test_kill_during_ros2_export_leaves_old(run, tmp_path):
    target = tmp_path / "bag"
    assert_ok(["export", run, "--ros2-bag", target])
    before = digest(target)
    res = child(KILL_IN_BAG, ["export", run, "--ros2-bag", target])
    assert res.returncode == -signal.SIGKILL
    assert digest(target) == before and len(hidden(target)) == 1
    assert_ok(["export", run, "--ros2-bag", target])
    assert hidden(target) == [] and digest(target) == before  # same run: the same bag again


@pytest.mark.slow
def test_kill_between_the_two_renames_leaves_none(run, tmp_path):
    """Without RENAME_EXCHANGE the swap takes two renames; a kill between them leaves no bag
    (the old one moved aside to .bag.old-PID), which the next export puts back, then replaces."""
    target = tmp_path / "bag"
    assert_ok(["export", run, "--ros2-bag", target])
    before = digest(target)
    res = child(KILL_BETWEEN_RENAMES, ["export", run, "--ros2-bag", target])
    assert res.returncode == -signal.SIGKILL
    assert not target.exists() and len(hidden(target)) == 1
    aside = tmp_path / f".bag.old-{hidden(target)[0].rsplit('-', 1)[1]}"
    assert digest(aside) == before
    assert_ok(["export", run, "--ros2-bag", target])
    assert hidden(target) == [] and not aside.exists() and digest(target) == before


@pytest.mark.slow
@pytest.mark.parametrize("flag,name", [("--mcap", "r.mcap"), ("--ros2-bag", "bag")])
def test_file_size_limit_refused_in_one_line_old_kept(plain_run, tmp_path, flag, name):
    target = tmp_path / name
    assert_ok(["export", plain_run, flag, target])
    before = digest(target)
    res = child("", ["export", plain_run, flag, target], limit=10_000)  # the zstd bag: 27 kB
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert f"replay: error: {flag} {target}: cannot write: File too large" in lines[0]
    assert digest(target) == before and hidden(target) == []


def test_stale_temporaries_of_dead_exports_only(tmp_path):
    target = tmp_path / "r.mcap"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / f".r.mcap.staging-{dead.pid}").write_bytes(b"partial")
    (tmp_path / f".r.mcap.staging-{dead.pid + 1000000}").mkdir()  # no such process either
    (tmp_path / ".r.mcap.staging-1").write_bytes(b"init is alive")  # a live process: kept
    (tmp_path / ".r.mcap.staging-x").write_bytes(b"not ours")  # not a pid: kept
    export_set(target, "mcap").recover()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".r.mcap.staging-1", ".r.mcap.staging-x"]
    assert export_set(target, "mcap").staging().name == f".r.mcap.staging-{os.getpid()}"


def test_directory_swap(tmp_path):
    old, new = tmp_path / "bag", tmp_path / "new"
    old.mkdir()
    (old / "a").write_text("old")
    new.mkdir()
    (new / "b").write_text("new")
    publish_dir(new, old)
    assert [p.name for p in old.iterdir()] == ["b"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]  # the old directory removed, by either swap
    (tmp_path / "c").mkdir()
    assert exchange(old, tmp_path / "c") in (True, False)  # supported here or not, never an exception


def test_estimates_read_one_run_and_stop(tmp_path):
    """Only run 0 is parsed: a damaged later run does not matter, and rows out of order are refused."""
    import gzip

    from replay.outputs.run_data import read_estimates

    head = "run,k,t,x0,P00,err_x\n"
    rows = [f"0,{k},{k / 10:.10g},{k},0.5,0.1\n" for k in range(5)] + ["1,0,0,9,9,9\n", "garbage\n"]
    path = tmp_path / "e.csv.gz"
    with gzip.open(path, "wt") as fh:
        fh.write(head + "".join(rows))
    est = read_estimates(path)
    assert est["x"][:, 0].tolist() == [0, 1, 2, 3, 4] and est["t"].tolist() == [0, 0.1, 0.2, 0.3, 0.4]
    with gzip.open(path, "wt") as fh:
        fh.write(head + rows[1] + rows[0])
    from replay.util.errors import DataError

    with pytest.raises(DataError, match="rows of run 0 are not its steps"):
        read_estimates(path)


def test_missing_run_dir_one_line(tmp_path):
    assert_refused(["export", tmp_path / "nope", "--mcap", tmp_path / "x.mcap"],
                   r"nope/manifest\.json.*not a `replay eval` output directory")


def test_library_write_never_replaces_a_foreign_file(tmp_path):
    """write_mcap (the function behind the export) keeps someone else's file, and no temporary."""
    from test_export_mcap import synthetic_run

    from replay.outputs.export_mcap import write_mcap
    from replay.util.errors import ReplayError

    target = tmp_path / "theirs.mcap"
    target.write_bytes(b"\x89MCAP0\r\nsomeone else's")
    with pytest.raises(ReplayError, match="theirs.mcap: exists and is not an MCAP written by replay"):
        write_mcap(target, *synthetic_run(n=800))
    assert target.read_bytes() == b"\x89MCAP0\r\nsomeone else's" and hidden(target) == []


def test_eval_exports_checked_before_the_evaluation(tmp_path):
    """`replay eval --mcap/--ros2-bag` can refuse its export targets before computing anything."""
    from replay.outputs.export_safety import check_eval_exports
    from replay.util.errors import ReplayError

    data, mapping = tmp_path / "log.csv", tmp_path / "map.toml"
    data.write_text("time,depth\n0,1\n")
    mapping.write_text("")
    with pytest.raises(ReplayError, match=r"--mcap .*log\.csv: is an input of this command"):
        check_eval_exports(tmp_path / "run", data, None, str(data))
    with pytest.raises(ReplayError, match=r"--ros2-bag .*map\.toml: is an input of this command"):
        check_eval_exports(tmp_path / "run", None, mapping, str(data), mapping=mapping)
    check_eval_exports(tmp_path / "run", tmp_path / "r.mcap", tmp_path / "bag", str(data), mapping=mapping)
