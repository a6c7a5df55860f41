"""The one output set (replay/util/output_set.py): claim -> check -> stage -> publish -> recover.

Each test uses the class directly (no evaluation): a set of files published as a whole, a kill at
each step of publishing (the fault hooks of replay.util.staging, in a child process) leaving the
old set or the new one, refusals onto, around and inside an input, and two processes claiming
one target.
"""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from replay.util.errors import ReplayError
from replay.util.output_set import OutputSet
from replay.util.staging import MARKER

KIND = "test set"


def publish(target, files: dict, **kw) -> None:
    with OutputSet(target, KIND, **kw).staged() as d:
        for name, text in files.items():
            (d / name).write_text(text)


def contents(target) -> dict:
    return {p.name: p.read_text() for p in sorted(target.iterdir()) if p.name != MARKER}


def siblings(target) -> list[str]:
    return sorted(p.name for p in target.parent.iterdir() if p.name != target.name)


def test_claim_check_publish_replaces_the_whole_set(tmp_path):
    out = tmp_path / "deep" / "out"
    s = OutputSet(out, KIND, what="--out")
    assert s.check() == out.resolve() and not (tmp_path / "deep").exists()  # checking writes nothing
    with s.claim() as held:
        assert held == out.resolve()
        publish(out, {"a.csv": "1", "b.csv": "2"})
    assert contents(out) == {"a.csv": "1", "b.csv": "2"}
    assert json.loads((out / MARKER).read_text()) == {"tool": "replay", "kind": KIND, "files": ["a.csv", "b.csv"]}
    publish(out, {"c.csv": "3"})  # ours: replaced as a whole, a.csv and b.csv gone
    assert contents(out) == {"c.csv": "3"}
    assert siblings(out) == [".out.lock"]  # no staging or moved-aside directory left


def test_what_is_not_ours_is_refused_in_one_line_and_kept(tmp_path):
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    with pytest.raises(ReplayError, match=r"^--out .*theirs: is a non-empty directory that is not a test set output"):
        OutputSet(theirs, KIND, what="--out").check()
    with pytest.raises(ReplayError, match="not a test set output"):
        publish(theirs, {"a": "1"}, what="--out")
    assert contents(theirs) == {"notes.txt": "mine"} and siblings(theirs) == []
    out = tmp_path / "out"
    publish(out, {"a": "1"})
    (out / "added.txt").write_text("the user's")  # a file added to our set: the set is no longer ours
    with pytest.raises(ReplayError, match=r"holds 'added.txt', which is not part of the test set output"):
        publish(out, {"a": "2"})
    assert contents(out) == {"a": "1", "added.txt": "the user's"}
    with pytest.raises(ReplayError, match=r"holds a 'test set' output, not a other output"):
        OutputSet(out, "other").check()
    with pytest.raises(ReplayError, match=r"^output .*out: exists; refusing to replace it"):
        OutputSet(out).check()  # neither a kind nor a rule: nothing existing is ours
    assert OutputSet(tmp_path / "empty").check() == (tmp_path / "empty").resolve()


def test_refused_onto_around_or_inside_an_input(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "log.csv").write_text("t\n0\n")
    log = data / "log.csv"
    cases = [
        (log, [log, None], "is an input of this command; refusing to overwrite it"),
        (tmp_path, [log], "contains the input"),
        (data / "out", [data], "lies inside the input"),
        (log, [data], "lies inside the input"),
    ]
    for target, inputs, why in cases:
        with pytest.raises(ReplayError, match=rf"^--out {target}: {why}"):
            OutputSet(target, KIND, what="--out", inputs=inputs).check()
        with pytest.raises(ReplayError, match=why):  # and again at publication, before anything is written
            publish(target, {"a": "1"}, inputs=inputs)
    assert log.read_text() == "t\n0\n"
    link = tmp_path / "link"
    link.symlink_to(data)  # a link to an input is the input
    with pytest.raises(ReplayError, match="lies inside the input"):
        OutputSet(link / "out", KIND, inputs=[data]).check()
    with pytest.raises(ReplayError, match=r"--mcap .*a: overlaps the other export target .*a/b"):
        OutputSet(tmp_path / "a", what="--mcap", others=[tmp_path / "a" / "b"], rule=lambda p, s: None).check()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "link"]  # nothing written by a refusal


def test_a_failed_write_is_one_line_and_leaves_the_old_set(tmp_path):
    out = tmp_path / "out"
    publish(out, {"a": "old"})
    with pytest.raises(ReplayError) as err, OutputSet(out, KIND, what="--out").staged() as d:
        (d / "a").write_text("new, half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert str(err.value) == f"--out {out}: cannot write (No space left on device); the previous output, if any, is unchanged"
    assert contents(out) == {"a": "old"} and siblings(out) == []
    with pytest.raises(ValueError), OutputSet(out, KIND).staged() as d:  # any other error: as it is, old kept
        raise ValueError("a bug")
    assert contents(out) == {"a": "old"} and siblings(out) == []


def test_a_file_is_replaced_in_one_step_and_only_by_its_rule(tmp_path):
    target = tmp_path / "r.txt"

    def ours(p, shown):
        if p.exists() and p.read_text().startswith("theirs"):
            raise ReplayError(f"--plot {shown}: not ours")

    for text in ("one", "two"):
        with OutputSet(target, what="--plot", rule=ours, file=True).staged() as tmp:
            assert tmp.name == f".r.txt.staging-{os.getpid()}" and not tmp.exists()
            tmp.write_text(text)
        assert target.read_text() == text and siblings(target) == []
    target.write_text("theirs")
    with pytest.raises(ReplayError, match="not ours"), OutputSet(target, rule=ours, file=True).staged() as tmp:
        tmp.write_text("three")
    assert target.read_text() == "theirs" and siblings(target) == []


CHILD = """
import sys
from pathlib import Path
from pathlib import Path
from replay.util.output_set import OutputSet
target, file = Path(sys.argv[1]), sys.argv[2] == "file"
with OutputSet(target, None if file else "test set", rule=(lambda p, s: None) if file else None, file=file).staged() as d:
    if file:
        d.write_text("new")
    else:
        for name in ("a", "b"):
            (d / name).write_text("new")
"""


def killed(target, point: str, *, file=False, no_exchange=False) -> None:
    env = {**os.environ, "REPLAY_FAULT": point}
    if no_exchange:
        env["REPLAY_NO_EXCHANGE"] = "1"
    res = subprocess.run([sys.executable, "-c", CHILD, str(target), "file" if file else "dir"], env=env,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == -9, res.stderr  # SIGKILL at the fault point


@pytest.mark.parametrize("point,no_exchange", [("written", False), ("swapped", False), ("written", True),
                                               ("aside", True)])
def test_a_kill_at_any_step_leaves_old_or_new_and_the_next_write_recovers(tmp_path, point, no_exchange):
    out = tmp_path / "out"
    publish(out, {"a": "old", "b": "old"})
    killed(out, point, no_exchange=no_exchange)
    after = contents(out) if out.exists() else None
    assert after in ({"a": "old", "b": "old"}, {"a": "new", "b": "new"}, None)
    # None only when killed with the old set moved aside: the next write puts it back first
    assert (after is None) == (point == "aside")
    if point == "swapped":
        assert after == {"a": "new", "b": "new"}  # exchanged: the new set is in place
    s = OutputSet(out, KIND)
    s.recover()
    assert contents(out) == (after or {"a": "old", "b": "old"}) and siblings(out) == []
    publish(out, {"c": "next"})
    assert contents(out) == {"c": "next"} and siblings(out) == []


def test_a_kill_while_writing_a_file_leaves_the_old_file(tmp_path):
    target = tmp_path / "r.txt"
    target.write_text("old")
    killed(target, "written", file=True)
    assert target.read_text() == "old" and len(siblings(target)) == 1  # the dead writer's staging file
    with OutputSet(target, rule=lambda p, s: None, file=True).staged() as tmp:  # recovers, then writes
        tmp.write_text("next")
    assert target.read_text() == "next" and siblings(target) == []


HOLD = """
import sys, time
from pathlib import Path
from replay.util.output_set import OutputSet
with OutputSet(sys.argv[1], what="--out").claim():
    print("held", flush=True)
    time.sleep(float(sys.argv[2]))
    Path(sys.argv[1] + ".released").write_text("")  # still holding the lock
"""


def test_concurrent_claims_refused_with_the_holders_pid_or_waited_for(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(out), "60"], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "held\n"
        with pytest.raises(ReplayError) as err, OutputSet(out, what="--out").claim():
            pass
        assert str(err.value) == (
            f"--out {out}: another replay eval process (pid {proc.pid}) is writing to it; "
            "wait for it to finish or pass --wait"
        )
    finally:
        proc.kill()
        proc.wait()
    with OutputSet(out, what="--out").claim():  # the kernel released the dead holder's lock
        pass
    short = subprocess.Popen([sys.executable, "-c", HOLD, str(out), "1"], stdout=subprocess.PIPE, text=True)
    assert short.stdout.readline() == "held\n"
    assert not (tmp_path / "out.released").exists()
    with OutputSet(out, what="--out").claim(wait=True):  # blocks until the holder leaves its block
        assert (tmp_path / "out.released").exists()
        assert (tmp_path / ".out.lock").read_text() == f"{os.getpid()}\n"  # the holder's pid, now ours
    short.wait()


def test_the_campaign_api_refuses_a_directory_that_is_not_a_campaigns(tmp_path):
    """replay.run_campaign's out has the rule of `replay campaign run --out` (the campaign's OutputSet)."""
    import replay

    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    with pytest.raises(ReplayError, match=r"^out .*theirs: is a non-empty directory that is not a replay campaign"):
        replay.run_campaign(Path(__file__).parents[1] / "campaigns" / "example.toml", out=theirs, workers=1)
    assert sorted(p.name for p in theirs.iterdir()) == ["notes.txt"]


def test_inspect_write_mapping_never_onto_or_inside_the_bag(tmp_path):
    """`replay inspect BAG --write-mapping FILE`: FILE written in one step, refused onto or inside BAG."""
    import numpy as np
    from hostile import assert_ok, assert_refused

    from replay.sim.auv_bag import make_bag

    bag = tmp_path / "auv"
    make_bag(bag, np.random.default_rng(3), duration=5.0)
    before = sorted((p.name, p.stat().st_size) for p in bag.iterdir())
    assert_refused(["inspect", bag, "--write-mapping", bag / "map.toml"],
                   r"--write-mapping .*auv/map\.toml: lies inside the input .*auv; refusing to write there")
    assert sorted((p.name, p.stat().st_size) for p in bag.iterdir()) == before
    assert_ok(["inspect", bag, "--write-mapping", tmp_path / "m" / "map.toml"])
    import tomllib

    mapping = tomllib.loads((tmp_path / "m" / "map.toml").read_text())
    assert mapping["channels"]["dvl"]["topic"] == "/dvl/twist"
    assert mapping["reference"]["position"]["topic"] == "/reference/pose"
    assert sorted(p.name for p in (tmp_path / "m").iterdir()) == ["map.toml"]  # no temporary left


def test_eval_tune_out_is_checked_before_any_tune(tmp_path):
    """`replay eval --tune N --out DIR`: DIR absent, empty or a --tune directory; never a foreign one."""
    from hostile import assert_refused

    from replay.tune.write import repeats_set

    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    assert_refused(["eval", "sim/linear", "-f", "kf", "--tune", "3", "--out", theirs],
                   r"^replay: error: --out .*theirs: holds 'notes.txt', which is not part of a replay eval --tune output")
    assert sorted(p.name for p in theirs.iterdir()) == ["notes.txt"]
    ours = tmp_path / "ours"
    for d in ("tune-0", "tune-1", "units"):
        (ours / d).mkdir(parents=True)
    (ours / "tuned.csv").write_text("")
    assert repeats_set(ours).check() == ours.resolve()
    with pytest.raises(ReplayError, match="lies inside the input"):
        repeats_set(ours / "tune-0", [ours]).check()
