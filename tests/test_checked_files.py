"""Issue 33, items 2, 3, 6 and 10 (parts): every archive a command reads is verified (results.json
included), outputs never overwrite what they did not create, stamps survive conversion exactly,
short downloads are never stored, campaign_results and campaign --out refuse foreign paths."""
from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli.main import main
from replay.trajectory.base import make
from replay.trajectory.files import write_tum
from replay.util import sealed


def refused(args, message):
    r = CliRunner().invoke(main, list(map(str, args)))
    lines = r.output.strip().splitlines()
    assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("replay: error:"), r.output
    assert message in lines[0], r.output
    return lines[0]


def ok(args):
    r = CliRunner().invoke(main, list(map(str, args)))
    assert r.exit_code == 0, r.output
    return r.output


@pytest.fixture
def files(tmp_path):
    n = 60
    t = 10.0 + np.arange(n) * 0.1
    s = np.arange(n, dtype=float)
    p = np.column_stack([s, np.sin(s / 5), np.zeros(n)])
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    write_tum(tmp_path / "gt.tum", make(t, p, q, source="gt"))
    write_tum(tmp_path / "est.tum", make(t, p * 1.01, q, source="est"))
    return tmp_path


@pytest.fixture
def saved(files):
    out = files / "res"
    ok(["score", files / "gt.tum", files / "est.tum", "--save-results", out])
    return out, json.loads((out / "results.json").read_text())


def _write(out, meta, reseal=False):
    if reseal:
        meta = dict(meta, results_sha256=sealed.digest(meta, "results_sha256"))
    (out / "results.json").write_text(json.dumps(meta, indent=1))


def test_an_edited_statistic_is_refused(saved):
    out, meta = saved
    rmse = meta["estimates"][0]["stats"]["ape"]["trans"]["rmse"]
    assert rmse > 0.1
    table = ok(["res", out, "--format", "csv"])
    assert repr(rmse) in table or f"{rmse}" in table
    edited = json.loads(json.dumps(meta))
    edited["estimates"][0]["stats"]["ape"]["trans"]["rmse"] = 0.001
    _write(out, edited)
    refused(["res", out], "results.json: content differs from its SHA-256 (results_sha256): edited or damaged")
    _write(out, meta)  # re-indented, same values: still verified
    assert ok(["res", out, "--format", "csv"]) == table


def test_an_emptied_file_list_is_refused(saved):
    out, meta = saved
    _write(out, dict(meta, files={}))
    refused(["res", out], "content differs from its SHA-256")
    _write(out, dict(meta, files={}), reseal=True)
    refused(["res", out], "results.json: lists no files (every archive holds ape.parquet, leaderboard.csv)")
    files = {k: v for k, v in meta["files"].items() if k != "ape.parquet"}
    _write(out, dict(meta, files=files), reseal=True)
    refused(["res", out], "does not list ape.parquet")
    _write(out, dict(meta, files=dict(meta["files"], **{"results.json": "0" * 64})), reseal=True)
    refused(["res", out], "results.json is missing (listed in results.json)")


def test_a_version_1_archive_is_refused_saying_how_to_recreate_it(saved):
    out, meta = saved
    old = {k: v for k, v in meta.items() if k != "results_sha256"}
    _write(out, dict(old, version=1))
    line = refused(["res", out], "archive version 1")
    assert "recreate it with replay score REF EST... --save-results" in line
