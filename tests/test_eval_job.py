"""``replay eval`` as one library call (replay.outputs.eval_job.run_eval), shared by the command line and
``replay.evaluate(..., out=...)``: the same output set, the same refusals, nothing computed when refused."""
import csv
import json

import pytest
from click.testing import CliRunner

import replay
from replay.cli import main
from replay.util.errors import ReplayError

NUMBERS = ("filter", "config_hash", "runs", "seed", "pos_rmse", "pos_rmse_ci95", "anees")


def _rows(path):
    return [{k: r[k] for k in NUMBERS} for r in csv.DictReader(open(path / "leaderboard.csv"))]


def test_api_out_writes_the_commands_output_set(tmp_path):
    ev = replay.evaluate("sim/ungm", filters="ekf,ukf", runs=3, seed=4, out=tmp_path / "api")
    res = CliRunner().invoke(main, ["eval", "sim/ungm", "-f", "ekf,ukf", "--runs", "3", "--seed", "4",
                                    "-o", str(tmp_path / "cli"), "-q"])
    assert res.exit_code == 0, res.output
    api, cli = _rows(tmp_path / "api"), _rows(tmp_path / "cli")
    assert api == cli and [r["filter"] for r in api] == ["ekf", "ukf"]
    assert [float(r["pos_rmse"]) for r in api] == [r["pos_rmse"] for r in ev.rows]
    in_memory = replay.evaluate("sim/ungm", filters="ekf,ukf", runs=3, seed=4)
    assert [r["pos_rmse"] for r in in_memory.rows] == [r["pos_rmse"] for r in ev.rows]
    man = json.loads((tmp_path / "api" / "manifest.json").read_text())
    assert man["config"]["runs"] == 3 and man["config"]["filters"] == ["ekf", "ukf"]


def test_api_out_refuses_as_the_command_does_before_computing(tmp_path, monkeypatch):
    out = tmp_path / "o"
    replay.evaluate("sim/ungm", filters="ekf", runs=1, out=out)
    before = (out / "leaderboard.csv").read_bytes()
    from replay.run import evaluation

    def computed(*a, **k):
        raise AssertionError("computed although refused")

    monkeypatch.setattr(evaluation, "run_block", computed)
    with pytest.raises(ReplayError, match=r"^--out .*o: holds an earlier replay eval output; pass --force"):
        replay.evaluate("sim/ungm", filters="ekf", runs=2, out=out)
    with pytest.raises(ReplayError, match=r"^--baseline 'pf': not among --filters \(ekf\)"):
        replay.evaluate("sim/ungm", filters="ekf", baseline="pf", out=tmp_path / "p")
    assert (out / "leaderboard.csv").read_bytes() == before and not (tmp_path / "p").exists()
    monkeypatch.undo()
    replay.evaluate("sim/ungm", filters="ekf", runs=2, out=out, force=True)
    assert [r["runs"] for r in _rows(out)] == ["2"]
