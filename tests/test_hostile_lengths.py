"""Hostile input to ``replay score --lengths``: one line, exit 2, no traceback, nothing written."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli.main import main
from replay.cli.score import score_cmd
from replay.trajectory.base import make
from replay.trajectory.files import write_tum

if "score" not in main.commands:
    main.add_command(score_cmd)


@pytest.fixture
def files(tmp_path):
    n = 101
    t = 10.0 + np.arange(n) * 0.1
    p = np.column_stack([np.arange(n) * 1.0, np.sin(np.arange(n) * 0.1), np.zeros(n)])
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    write_tum(tmp_path / "gt.tum", make(t, p, q, source="gt"))
    write_tum(tmp_path / "est.tum", make(t, p * 1.01, q, source="est"))
    rows = "".join(f"{a:.3f},{b},{c},0\n" for a, b, c in zip(t, p[:, 0], p[:, 1]))
    (tmp_path / "pos.csv").write_text("t,x,y,z\n" + rows)
    return tmp_path


@pytest.mark.parametrize("spec, message", [
    ("0", "'0' must be a positive length"),
    ("150%", "'150%' must be a positive length in metres or a percentage in (0, 100]%"),
    ("-10", "'-10' must be a positive"),
    ("nan", "'nan' must be a positive"),
    ("inf", "'inf' must be a positive"),
    ("ten", "'ten' is neither a length in metres nor a percentage"),
    ("10,,20", "expected a comma-separated list"),
    ("10,10", "a length is given twice"),
    ("10%,10%", "a length is given twice"),
    ("...,800", "'...' needs two values before it"),
    ("100,200,...", "'...' needs two values before it and one after"),
    ("100,200,...,850", "850 is not on the step 100"),
    ("10%,20,...,50", "'...' needs increasing values of one unit"),
    ("1,2,...,1000", "at most 100"),
    ("0.001%", "0 m of a reference path"),
])
def test_bad_lengths_refused_in_one_line(files, spec, message):
    out = files / "res.csv"
    r = CliRunner().invoke(main, ["score", str(files / "gt.tum"), str(files / "est.tum"), "--lengths", spec,
                                  "-o", str(out)])
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("replay: error: --lengths") and message in lines[0], r.output
    assert not out.exists()


def test_positions_only_refused(files):
    r = CliRunner().invoke(main, ["score", str(files / "gt.tum"), str(files / "pos.csv"), "--lengths", "10"])
    assert r.exit_code == 2 and "needs orientations" in r.output and "Traceback" not in r.output, r.output


def test_unknown_method_refused(files):
    r = CliRunner().invoke(main, ["score", str(files / "gt.tum"), str(files / "est.tum"), "--lengths", "10",
                                  "--lengths-method", "tum"])
    assert r.exit_code == 2 and "tum" in r.output


def test_length_longer_than_the_track_reports_no_sample(files):
    """rpg: "Too few samples! Will not compute." -- no statistics (NaN, 0 samples), not a number."""
    out = files / "res.csv"
    r = CliRunner().invoke(main, ["score", str(files / "gt.tum"), str(files / "est.tum"), "--lengths", "500",
                                  "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "length 500m = 500 m: 0 sub-trajectories" in r.output
    text = out.read_text()
    assert ",0," in text and "nan" in text.lower()
