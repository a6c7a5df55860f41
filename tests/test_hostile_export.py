"""Hostile export targets and damaged runs: `replay export` / `replay eval --mcap|--ros2-bag`
refuse in one line, and no input (dataset bag, MCAP, mapping, run directory) or foreign
file is touched. Before, `--ros2-bag DIR` deleted any directory holding metadata.yaml
(the input bag included, exit 0) and `--mcap FILE` overwrote the input MCAP."""
import gzip
import hashlib
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hostile import assert_ok, assert_refused, register

MAPPING = Path(__file__).resolve().parents[1] / "docs" / "mappings" / "auv.toml"


def make_world(root: Path) -> Path:
    """A small synthetic bag (as a directory and as its .mcap file), a mapping, two runs on
    them, and things that are not ours: an MCAP of another writer, a ROS 2 bag without our
    mark, a text file, a non-empty directory."""
    from mcap.writer import Writer

    from replay.sim.auv_bag import make_bag

    data = root / "data"
    make_bag(data / "auv", np.random.default_rng(1), duration=5.0)
    shutil.copy(MAPPING, data / "map.toml")
    for run, src in (("run_m", data / "auv" / "auv.mcap"), ("run_b", data / "auv")):
        assert_ok(["eval", src, "--mapping", data / "map.toml", "--task", "position", "-f", "ekf",
                   "-o", root / run])
    with open(root / "foreign.mcap", "wb") as fh:
        w = Writer(fh)
        w.start()
        w.finish()
    make_bag(root / "foreign_bag", np.random.default_rng(2), duration=2.0)
    (root / "notes.txt").write_text("not an export\n")
    (root / "stuff").mkdir()
    (root / "stuff" / "keep.txt").write_text("mine\n")
    (root / "link.mcap").symlink_to(data / "auv" / "auv.mcap")
    return root


def tree_digest(root: Path, skip=("eval_out",)) -> str:
    """sha256 over every path, link target and file content under ``root`` (but ``skip``)."""
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root)
        if rel.parts[0] in skip:
            continue
        h.update(str(rel).encode())
        if p.is_symlink():
            h.update(os.readlink(p).encode())
        elif p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return make_world(tmp_path_factory.mktemp("world"))


def _damaged(world, name, edit):
    """A copy of run_m whose estimates or manifest ``edit`` damages."""
    run = world / "out" / name
    if not run.exists():
        shutil.copytree(world / "run_m", run)
        edit(run)
    return run


def truncate_estimates(run):
    data = (run / "estimates" / "ekf.csv.gz").read_bytes()
    (run / "estimates" / "ekf.csv.gz").write_bytes(data[:len(data) // 2])


def shuffle_steps(run):
    path = run / "estimates" / "ekf.csv.gz"
    with gzip.open(path, "rt") as fh:
        lines = fh.read().splitlines()
    lines[2], lines[3] = lines[3], lines[2]
    with gzip.open(path, "wt") as fh:
        fh.write("\n".join(lines) + "\n")


def filter_path_name(run):
    text = (run / "manifest.json").read_text()
    (run / "manifest.json").write_text(text.replace('"ekf"', '"../../ekf"', 1))


CASES = {
    # export onto or around an input
    "export-mcap-is-input-mcap": (lambda w: ["export", w / "run_m", "--mcap", w / "data/auv/auv.mcap"],
                                  r"--mcap .*auv\.mcap: is an input of this command"),
    "export-ros2-is-input-bag": (lambda w: ["export", w / "run_b", "--ros2-bag", w / "data/auv"],
                                 r"--ros2-bag .*data/auv: is an input of this command"),
    "export-ros2-contains-input": (lambda w: ["export", w / "run_b", "--ros2-bag", w / "data"],
                                   r"--ros2-bag .*data: contains the input .*(auv|map\.toml)"),
    "export-mcap-inside-input-bag": (lambda w: ["export", w / "run_b", "--mcap", w / "data/auv/new.mcap"],
                                     r"--mcap .*new\.mcap: lies inside the input .*data/auv"),
    "export-mcap-inside-run-dir": (lambda w: ["export", w / "run_m", "--mcap", w / "run_m/x.mcap"],
                                   r"--mcap .*x\.mcap: lies inside the input .*run_m"),
    "export-mcap-is-mapping": (lambda w: ["export", w / "run_m", "--mcap", w / "data/map.toml"],
                               r"--mcap .*map\.toml: is an input of this command"),
    "export-mcap-link-to-input": (lambda w: ["export", w / "run_m", "--mcap", w / "link.mcap"],
                                  r"--mcap .*link\.mcap: is an input of this command"),
    # replacing what this tool did not write
    "export-mcap-onto-foreign-mcap": (lambda w: ["export", w / "run_m", "--mcap", w / "foreign.mcap"],
                                      r"foreign\.mcap: exists and is not an MCAP written by replay"),
    "export-mcap-onto-text-file": (lambda w: ["export", w / "run_m", "--mcap", w / "notes.txt"],
                                   r"notes\.txt: exists and is not an MCAP written by replay"),
    "export-mcap-onto-directory": (lambda w: ["export", w / "run_m", "--mcap", w / "stuff"],
                                   r"--mcap .*stuff: is a directory"),
    "export-ros2-onto-foreign-bag": (lambda w: ["export", w / "run_m", "--ros2-bag", w / "foreign_bag"],
                                     r"foreign_bag: exists and is not a ROS 2 bag written by replay"),
    "export-ros2-onto-file": (lambda w: ["export", w / "run_m", "--ros2-bag", w / "notes.txt"],
                              r"notes\.txt: exists and is not a directory"),
    "export-ros2-onto-nonempty-dir": (lambda w: ["export", w / "run_m", "--ros2-bag", w / "stuff"],
                                      r"stuff: exists and is not a ROS 2 bag written by replay"),
    "export-mcap-parent-is-file": (lambda w: ["export", w / "run_m", "--mcap", w / "notes.txt/x.mcap"],
                                   r"--mcap .*x\.mcap: .*notes\.txt is a file, not a directory"),
    "export-targets-overlap": (lambda w: ["export", w / "run_m", "--mcap", w / "out/b/x.mcap",
                                          "--ros2-bag", w / "out/b"],
                               r"--mcap .*x\.mcap: overlaps the other export target .*out/b"),
    # the original bugs, through `replay eval`
    "eval-ros2-onto-input-bag": (lambda w: ["eval", w / "data/auv", "--mapping", w / "data/map.toml", "-t",
                                            "position", "-f", "ekf", "-o", w / "eval_out/a",
                                            "--ros2-bag", w / "data/auv"],
                                 r"--ros2-bag .*data/auv: is an input of this command"),
    "eval-mcap-onto-input-mcap": (lambda w: ["eval", w / "data/auv/auv.mcap", "--mapping", w / "data/map.toml",
                                             "-t", "position", "-f", "ekf", "-o", w / "eval_out/b",
                                             "--mcap", w / "data/auv/auv.mcap"],
                                  r"--mcap .*auv\.mcap: is an input of this command"),
    # damaged runs
    "export-estimates-truncated": (lambda w: ["export", _damaged(w, "trunc", truncate_estimates),
                                              "--mcap", w / "out/t.mcap"],
                                   r"ekf\.csv\.gz.*cannot read estimates"),
    "export-estimates-steps-out-of-order": (lambda w: ["export", _damaged(w, "shuffled", shuffle_steps),
                                                       "--mcap", w / "out/s.mcap"],
                                            r"ekf\.csv\.gz.*rows of run 0 are not its steps"),
    "export-manifest-filter-path": (lambda w: ["export", _damaged(w, "pathname", filter_path_name),
                                               "--mcap", w / "out/p.mcap"],
                                    r"manifest\.json.*filter name '\.\./\.\./ekf' is not a plain name"),
}
register(*CASES)


@pytest.mark.parametrize("case", sorted(CASES))
def test_refused_and_nothing_touched(world, case):
    args, match = CASES[case]
    args = args(world)
    before = tree_digest(world)
    assert_refused(args, match)
    assert tree_digest(world) == before  # inputs, runs, foreign files as they were; nothing new


def test_export_onto_own_outputs_replaces_them(world):
    """The only thing an export replaces: what an export wrote (MCAP header library, bag mark)."""
    from replay.adapters import bags
    from replay.outputs.export_safety import bag_marker, mcap_library

    out = world / "out" / "own"
    for run in ("run_m", "run_b"):
        res = assert_ok(["export", world / run, "--mcap", out / "r.mcap", "--ros2-bag", out / "bag"])
        assert "wrote" in res.stdout
    assert mcap_library(out / "r.mcap") == "replay" and bag_marker(out / "bag") == "replay export"
    assert bags.read(out / "bag", []).topics["/replay/ekf/odom"].count == 100
    assert sorted(p.name for p in out.iterdir()) == ["bag", "r.mcap"]  # no temporary left
