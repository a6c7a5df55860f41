"""Hostile campaign inputs (corpus: tests/hostile.py): manifests for ``replay rerun``,
campaign files, damaged result directories, and a second process on a locked campaign.

Each case is a one-line refusal naming the file (and the key or line), or, for a damaged
store under ``replay campaign run``, a counted repair: the damaged units are named,
counted and computed again, and the leaderboard equals the undamaged one.
"""
from __future__ import annotations

import copy
import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hostile import assert_ok, assert_refused, register

from replay.run.pipeline import Config, config_hash

CAMPAIGN = """\
[campaign]
name = "hostile"
runs = 3
seed = 1
batch = 3

[[dataset]]
id = "sim/auv-sonar"
params = { steps = 20 }

[[filter]]
name = "ukf"
params = { alpha = 0.5 }
"""


def _hashes(cfg: dict) -> dict:
    """The configuration hashes a consistent manifest records for ``cfg``."""
    return {f: config_hash(Config(cfg["dataset"], cfg["dataset_params"], cfg["first"], cfg["task"],
                                  cfg["task_params"], f, cfg["filter_params"][f], cfg["seed"], cfg["alignment"],
                                  cfg["divergence_threshold"], cfg["adapter"]).as_dict())
            for f in cfg["filters"]}


def _as_file_dataset(m):
    """A consistent manifest (hashes recomputed) of a CSV dataset whose checksum is null."""
    cfg = m["config"]
    cfg.update(dataset="lake.csv", adapter="lake", dataset_sha256=None)
    cfg["config_hashes"] = _hashes(cfg)
    for f, h in cfg["config_hashes"].items():
        m["results"][f]["config_hash"] = h


def _set(path, value):
    def edit(m):
        *head, last = path
        d = m
        for k in head:
            d = d[k]
        d[last] = value
    return edit


def _drop(path):
    def edit(m):
        *head, last = path
        d = m
        for k in head:
            d = d[k]
        del d[last]
    return edit


def _drop_rmse(m):
    del m["results"]["ukf"]["yaw_rmse"]


MANIFESTS = {  # id: (edit of the parsed manifest, or raw text, expected refusal)
    "manifest-null-checksum": (_as_file_dataset, r"config\.dataset_sha256: null, but lake\.csv is not a simulated"),
    "manifest-changed-config-hash": (_set(["config", "config_hashes", "ukf"], "0123456789abcdef"),
                                     r"config\.config_hashes\.ukf: 0123456789abcdef does not match the recorded "
                                     r"configuration \(which hashes to [0-9a-f]{16}\)"),
    "manifest-edited-parameter": (_set(["config", "filter_params", "ukf", "alpha"], 0.75),
                                  r"config\.config_hashes\.ukf: [0-9a-f]{16} does not match"),
    "manifest-deleted-rmse-key": (_drop_rmse, r"results\.ukf\.yaw_rmse: missing: the recorded RMSE values"),
    "manifest-missing-filter-results": (_drop(["results", "ukf"]), r"results\.ukf: missing"),
    "manifest-missing-filter-params": (_drop(["config", "filter_params", "ukf"]),
                                       r"config\.filter_params\.ukf: missing"),
    "manifest-runs-as-text": (_set(["config", "runs"], "3"),
                              r"config\.runs: expected an integer in \[1, 1000000\], got str '3'"),
    "manifest-filters-as-text": (_set(["config", "filters"], "ukf"), r"config\.filters: expected a list"),
    "manifest-rmse-as-text": (_set(["results", "ukf", "pos_rmse"], "1.2"),
                              r"results\.ukf\.pos_rmse: expected a number, got str '1\.2'"),
    "manifest-runs-bool": (_set(["config", "runs"], True),
                           r"config\.runs: expected an integer in \[1, 1000000\], got bool"),
    "manifest-bad-checksum": (_set(["config", "dataset_sha256"], "abc"), r"config\.dataset_sha256: expected 64"),
    "manifest-no-config": (_drop(["config"]), r"config: missing: not a replay manifest"),
    "manifest-not-json": ("this is not json {", r"not a replay manifest \(not valid JSON"),
    "manifest-empty": ("", r"empty file, not a replay manifest"),
    "manifest-truncated": (None, r"not a replay manifest \(not valid JSON"),
    "manifest-array": ("[1, 2, 3]", r"not a replay manifest \(a JSON list, not an object\)"),
}

CAMPAIGN_FILES = {  # id: (edit of CAMPAIGN, expected refusal, its line)
    "campaign-toml-syntax": (('runs = 3', 'runs = = 3'), r"c\.toml: not valid TOML: .*line 3"),
    "campaign-unknown-key": (('seed = 1', 'sede = 1'), r"c\.toml:4: \[campaign\]: sede: unknown key \(known: "),
    "campaign-name-escapes-root": (('name = "hostile"', 'name = "../../x"'),
                                   r"c\.toml:2: name: '\.\./\.\./x' is not a plain name \(it contains a path sep"),
    "campaign-absolute-name": (('name = "hostile"', 'name = "/tmp/x"'),
                               r"c\.toml:2: name: '/tmp/x' is not a plain name \(it is an absolute path"),
    "campaign-name-backslash": (('name = "hostile"', 'name = "a\\\\b"'), r"c\.toml:2: name: .* path separator"),
    "campaign-name-dotdot": (('name = "hostile"', 'name = ".."'), r"c\.toml:2: name: '\.\.' is not a plain name"),
    "campaign-bad-parameter-type": (("alpha = 0.5", 'alpha = "yes"'),
                                    r"c\.toml:13: alpha: filter 'ukf': alpha must be a finite number .*got 'yes'"),
    "campaign-unknown-filter": (('name = "ukf"', 'name = "xkf"'), r"c\.toml:12: name: unknown filter 'xkf'"),
    "campaign-empty-filter-list": (("[[filter]]\nname = \"ukf\"\nparams = { alpha = 0.5 }\n", "filter = []\n"),
                                   r"c\.toml:\d+: \[\[dataset\]\]: filter: unknown key"),  # after [[dataset]]: its key
}

STORES = ["store-zero-length-record", "store-truncated-parquet", "store-wrong-columns", "store-flipped-byte",
          "store-damaged-config"]
register(*MANIFESTS, *CAMPAIGN_FILES, *STORES, "campaign-locked-by-another-process")


@pytest.fixture(scope="module")
def manifest(tmp_path_factory):
    """A valid manifest of two runs of the UKF on a short simulated track (parsed, and its path)."""
    d = tmp_path_factory.mktemp("ev")
    assert_ok(["eval", "sim/auv-sonar", "-f", "ukf", "-p", "ukf.alpha=0.5", "--runs", "2",
               "--dataset-param", "steps=20", "-o", d / "ev"])
    path = d / "ev" / "manifest.json"
    return json.loads(path.read_text()), path


@pytest.mark.parametrize("case", list(MANIFESTS))
def test_hostile_manifest_refused_before_any_work(case, manifest, tmp_path, monkeypatch):
    from replay.run import rerun

    monkeypatch.setattr(rerun, "repeat", lambda *a, **k: pytest.fail("computed despite a bad manifest"))
    edit, match = MANIFESTS[case]
    good, good_path = manifest
    path = tmp_path / "manifest.json"
    if edit is None:  # truncated mid-way
        path.write_text(good_path.read_text()[:700])
    elif isinstance(edit, str):
        path.write_text(edit)
    else:
        m = copy.deepcopy(good)
        edit(m)
        path.write_text(json.dumps(m))
    line = assert_refused(["rerun", path], match)
    assert line.startswith(f"replay: error: {path}: ")


@pytest.mark.parametrize("case", list(CAMPAIGN_FILES))
def test_hostile_campaign_file_refused_with_its_line(case, tmp_path):
    (old, new), match = CAMPAIGN_FILES[case]
    assert old in CAMPAIGN
    path = tmp_path / "c.toml"
    path.write_text(CAMPAIGN.replace(old, new))
    assert_refused(["campaign", "run", path, "-o", tmp_path / "out"], match)
    assert not (tmp_path / "out").exists() and not (tmp_path / "x").exists()


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A computed campaign directory (3 units) and its leaderboard rows."""
    d = tmp_path_factory.mktemp("store")
    (d / "c.toml").write_text(CAMPAIGN)
    assert_ok(["campaign", "run", d / "c.toml", "-o", d / "out", "-w", "1", "-q"])
    return d, _rows(d / "out")


def _rows(out):
    with open(Path(out) / "leaderboard.csv") as fh:
        return [{k: v for k, v in r.items() if k not in ("us_per_step", "version")} for r in csv.DictReader(fh)]


def _damage(case, unit: Path) -> tuple[str, str]:
    """Damage run 1 of the unit directory; (the damaged file's name, the expected problem)."""
    if case == "store-zero-length-record":
        (unit / "1.json").write_bytes(b"")
        return "1.json", "zero-length unit record"
    if case == "store-truncated-parquet":
        data = (unit / "1.parquet").read_bytes()
        (unit / "1.parquet").write_bytes(data[: len(data) // 2])
        return "1.parquet", rf"truncated \({len(data) // 2} bytes, its record says {len(data)}\)"
    if case == "store-wrong-columns":
        import pyarrow as pa
        import pyarrow.parquet as pq

        pq.write_table(pa.table({"k": [0, 1], "speed": [1.0, 2.0]}), unit / "1.parquet")
        return "1.parquet", "columns differ from the unit's"
    if case == "store-flipped-byte":  # inside the data pages: footer, columns and rows intact
        data = bytearray((unit / "1.parquet").read_bytes())
        data[100] ^= 0x01
        (unit / "1.parquet").write_bytes(bytes(data))
        return "1.parquet", "content differs from the checksum in its record"
    (unit / "config.json").write_text('{"dataset": "sim/auv-sonar"')
    return "config.json", "not valid JSON"


@pytest.mark.parametrize("case", STORES)
def test_damaged_store_refused_by_readers_and_recomputed_by_run(case, store, tmp_path):
    d, rows = store
    out = tmp_path / "out"
    shutil.copytree(d / "out", out)
    unit = next((out / "units").iterdir())
    name, problem = _damage(case, unit)
    hint = "run `replay campaign run` on its campaign file again"
    for args in (["leaderboard", out], ["report", out]):
        line = assert_refused(args, rf"{unit / name}: .*{problem}")
        assert hint in line
    res = assert_ok(["campaign", "run", d / "c.toml", "-o", out, "-w", "1", "-q"])
    if case == "store-damaged-config":
        assert f"rewrote 1 damaged configuration file: {unit / name}: not valid JSON" in res.stdout
        assert "nothing to do: all 3 units already stored" in res.stdout
    else:
        assert f"recomputed 1 damaged unit: {unit / name}: " in res.stdout
        assert "1 units computed, 0 failed" in res.stdout
    assert _rows(out) == rows
    assert_ok(["leaderboard", out])


def test_second_campaign_process_refused_naming_the_lock_and_its_pid(store, tmp_path):
    d, _ = store
    out = tmp_path / "out"
    out.mkdir()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, os, sys; f = open(sys.argv[1], 'a+'); fcntl.flock(f, fcntl.LOCK_EX); "
                               "f.truncate(0); f.write(str(os.getpid())); f.flush(); print('held', flush=True); "
                               "sys.stdin.read()", str(out / "campaign.lock")],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        assert_refused(["campaign", "run", d / "c.toml", "-o", out, "-w", "1", "-q"],
                       rf"{out / 'campaign.lock'}: another campaign process \(pid {holder.pid}\) is writing to "
                       rf"{out}; wait for it to finish or pass --wait")
        assert not (out / "units").exists()
    finally:
        holder.stdin.close()
        holder.wait(timeout=10)
