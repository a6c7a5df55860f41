"""The paths ``replay tune`` writes into ``tuned.toml`` are relative to that file (as a campaign
file's paths are read), so ``replay eval --tuned`` finds the recording and its mapping from any
working directory, and the file holds no absolute path of the machine that wrote it."""
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli import main

MAPPING = Path(__file__).resolve().parents[1] / "docs" / "mappings" / "auv.toml"


def _cli(*args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


@pytest.mark.slow  # two tune trials and an eval on a generated bag (about 15 s with compiled kernels)
def test_tuned_toml_paths_resolve_from_a_third_working_directory(tmp_path, monkeypatch):
    from replay.sim.auv_bag import make_bag

    make_bag(tmp_path / "data" / "auv", np.random.default_rng(3), duration=30.0)
    (tmp_path / "checkout" / "maps").mkdir(parents=True)
    (tmp_path / "checkout" / "maps" / "auv.toml").write_text(MAPPING.read_text())
    monkeypatch.chdir(tmp_path / "checkout")  # relative dataset, mapping and data dir; --out in another folder
    _cli("tune", "../data/auv", "--mapping", "maps/auv.toml", "-t", "fusion", "--train-segment", "0.6",
         "-f", "ekf", "-p", "ekf.q_scale=log[2,10]", "--trials", "2", "-n", "1", "-q",
         "--data-dir", "../data", "--out", "../results/deep/t")
    tuned = tmp_path / "results" / "deep" / "t" / "tuned.toml"
    text = tuned.read_text()
    assert str(tmp_path) not in text  # no machine path, the comment lines included
    doc = tomllib.loads(text)
    ds = doc["dataset"][0]
    assert ds["id"] == "../../../data/auv"  # relative to the file's folder results/deep/t
    assert ds["params"]["mapping"] == "../../../checkout/maps/auv.toml"
    assert ds["params"]["segment"] == "0.6:1"
    assert doc["campaign"]["data_dir"] == "../../../data"
    q = doc["filter"][0]["params"]["q_scale"]
    assert 2 <= q <= 10  # the default (1) is outside the space: the tuned value is written
    row = next(r for r in _board(tmp_path / "results" / "deep" / "t") if r["label"] == "ekf (tuned)")

    (tmp_path / "elsewhere" / "deeper").mkdir(parents=True)
    monkeypatch.chdir(tmp_path / "elsewhere" / "deeper")  # neither the tune's directory nor the file's
    _cli("eval", "../../data/auv", "--tuned", "../../results/deep/t/tuned.toml", "-q", "--out", "e")
    m = json.loads((tmp_path / "elsewhere" / "deeper" / "e" / "manifest.json").read_text())
    assert m["config"]["dataset_params"]["segment"] == "0.6:1"  # the tune's test data, from the file
    assert m["config"]["dataset_params"]["mapping"] == str(tmp_path / "checkout" / "maps" / "auv.toml")
    assert m["config"]["filter_params"]["ekf"]["q_scale"] == q
    assert float(m["results"]["ekf"]["pos_rmse"]) == float(row["pos_rmse"])  # the tune's held-out row


def _board(out: Path) -> list[dict]:
    import csv

    with open(out / "leaderboard.csv", newline="") as fh:
        return list(csv.DictReader(fh))
