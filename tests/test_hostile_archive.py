"""Hostile input to ``replay score --trials/--save-results``, ``replay res`` and ``replay convert``: one line,
exit 2, no traceback, nothing written."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli.main import main
from replay.trajectory.base import make
from replay.trajectory.files import write_tum
from replay.util import sealed

from cli_helpers import refused


@pytest.fixture
def files(tmp_path):
    n = 60
    t = 10.0 + np.arange(n) * 0.1
    s = np.arange(n, dtype=float)
    p = np.column_stack([s, np.sin(s / 5), np.zeros(n)])
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    write_tum(tmp_path / "gt.tum", make(t, p, q, source="gt"))
    for k in (1, 2):
        write_tum(tmp_path / f"est{k}.tum", make(t, p * (1 + 0.01 * k), q, source="est"))
    return tmp_path




def test_trials_refusals(files):
    gt = files / "gt.tum"
    refused(["score", gt, "--trials", f"{files}/nothing_*.txt"], "no file matches")
    refused(["score", gt, "--trials", f"a={files}/est*.tum", "--trials", f"a={files}/est1.tum"], "is given twice")
    refused(["score", gt], "no estimate")
    refused(["score", gt, "--trials", f"{files}/*.tum"], "is the reference itself")
    refused(["score", gt, files / "est1.tum", "--trials-plot", files / "b.png"], "give --trials")
    refused(["score", gt, "--trials", f"{files}/est*.tum", "--trials-plot", files / "b.gif"], "unsupported extension")
    assert not (files / "b.png").exists()
    write_tum(files / "late.tum", make(100.0 + np.arange(5.0), np.eye(5, 3), np.tile([0.0, 0, 0, 1], (5, 1)),
                                       source="late"))
    r = CliRunner().invoke(main, ["score", str(gt), "--trials", f"orb={files}/est1.tum", "--trials",
                                  f"orb={files}/late.tum", "-o", str(files / "lb.csv")])
    last = r.output.strip().splitlines()[-1]  # after the line of the trial scored before it
    assert r.exit_code == 2 and last.startswith("replay: error: trial orb/2 (") and "late.tum" in last, r.output
    assert "do not overlap" in last and "Traceback" not in r.output and not (files / "lb.csv").exists()


def test_save_results_refusals(files):
    gt, est = files / "gt.tum", files / "est1.tum"
    (files / "mine").mkdir()
    (files / "mine" / "notes.txt").write_text("keep me")
    refused(["score", gt, est, "--save-results", files / "mine"], "not a replay score results output")
    assert (files / "mine" / "notes.txt").read_text() == "keep me"
    refused(["score", gt, est, "--save-results", files], "contains the input")
    refused(["score", gt, est, "--save-results", gt], "is an input")


def test_res_refusals(files):
    refused(["res", files / "absent"], "no such directory")
    refused(["res", files], "not a results archive (no results.json")
    (files / "empty").mkdir()
    refused(["res", files / "empty"], "not a results archive")
    out = files / "a"
    assert CliRunner().invoke(main, ["score", str(files / "gt.tum"), str(files / "est1.tum"), "--save-results",
                                     str(out)]).exit_code == 0
    refused(["res", out, "--format", "docx"], "--format 'docx': expected one of csv, md, latex")
    refused(["res", out, "-o", files / "t.xlsx"], "give --format csv|md|latex")
    refused(["res", out, "--table", "trials"], "no trial set in these results")
    refused(["res", out, "--format", "csv", "-o", out / "results.json"], "lies inside the input")
    meta = json.loads((out / "results.json").read_text())
    data = (out / "ape.parquet").read_bytes()
    (out / "ape.parquet").write_bytes(data[:-20] + bytes(20))
    refused(["res", out], "ape.parquet: damaged")
    (out / "ape.parquet").write_bytes(data)
    (out / "results.json").write_text(json.dumps(dict(meta, estimates=[])))
    refused(["res", out], "results.json: content differs from its SHA-256")
    empty = dict(meta, estimates=[])
    (out / "results.json").write_text(json.dumps(dict(empty, results_sha256=sealed.digest(empty, "results_sha256"))))
    refused(["res", out], "an empty results archive")
    (out / "results.json").write_text(json.dumps(dict(meta, version=99)))
    refused(["res", out], "archive version 99")
    (out / "results.json").write_text("{not json")
    refused(["res", out], "results.json: unreadable")


def test_evo_save_as_answered(files):
    for flag in ("--save_as_tum", "--save_as_kitti", "--save_as_bag"):
        refused(["score", files / "gt.tum", files / "est1.tum", flag], "replay convert SOURCE OUT.tum")


def test_convert_refusals(files):
    refused(["convert", files / "gt.tum", files / "o.bin"], "the extension .bin does not say the format")
    refused(["convert", files / "gt.tum", files / "o.tum", "--format", "ply"], "--format 'ply': expected one of")
    refused(["convert", files / "gt.tum", files / "gt.tum"], "is an input of this command")
    refused(["convert", files / "absent.tum", files / "o.tum"], "no such file")
    (files / "d").mkdir()
    refused(["convert", files / "gt.tum", files / "d", "--format", "tum"], "is a directory")
    assert not (files / "o.tum").exists()


@pytest.mark.slow  # a subprocess killed in the middle of the write: about 3 s
def test_a_killed_save_leaves_the_old_archive(files):
    out = files / "a"
    assert CliRunner().invoke(main, ["score", str(files / "gt.tum"), str(files / "est1.tum"), "--save-results",
                                     str(out)]).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    env = dict(os.environ, REPLAY_FAULT="written")
    r = subprocess.run([sys.executable, "-m", "replay.cli", "score", str(files / "gt.tum"), str(files / "est2.tum"),
                        "--save-results", str(out)], env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode != 0
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    r = CliRunner().invoke(main, ["res", str(out)])
    assert r.exit_code == 0 and "est1" in r.output and "est2" not in r.output
