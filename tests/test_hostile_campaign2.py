"""Hostile campaign cases of issue 23 (corpus: tests/hostile.py).

Edited unit records and configuration indexes, a unit directory replaced by a file or
removed, campaign files with out-of-range, binary or oversized values, a full disk, a
25,000-configuration-style grid (no flush per configuration up front), the data
directory a campaign export reuses, and the source column of a merged leaderboard.
Each case is a one-line refusal naming the file (and the key), or a counted repair whose
leaderboard equals the undamaged one.
"""
from __future__ import annotations

import csv
import errno
import json
import os
import re
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest
from hostile import assert_ok, assert_refused, register
from test_hostile_campaign import CAMPAIGN
from test_hostile_campaign import _rows  # the leaderboard less its timing and version columns
from test_hostile_campaign import store  # noqa: F401 -- the fixture: a computed campaign of 3 units

STORES = ["store-edited-metric", "store-legacy-record-edited", "store-unit-dir-is-file", "store-unit-dir-missing",
          "store-index-edited", "store-config-json-removed"]
CAMPAIGN_FILES = {  # id: ((old, new, ...) edits of CAMPAIGN, expected refusal)
    "campaign-seed-negative": (("seed = 1", "seed = -1"), r"c\.toml:4: \[campaign\]: seed must be an integer "
                                                          r"in \[0, 9223372036854775807\] \(got -1\)"),
    "campaign-runs-billion": (("runs = 3", "runs = 1000000000"),
                              r"c\.toml:3: \[campaign\]: runs must be an integer in \[1, 1000000\] "
                              r"\(got 1000000000\)"),
    "campaign-divergence-negative": (("batch = 3", "batch = 3\ndivergence_threshold = -5.0"),
                                     r"c\.toml:6: \[campaign\]: divergence_threshold must be "
                                     r"a finite number > 0"),
    "campaign-name-300-chars": (('name = "hostile"', f'name = "{"n" * 300}"'),
                                r"c\.toml:2: name: 'n{40}\.\.\.' is not a plain name \(it is 300 bytes long, at "
                                r"most 240"),
    "campaign-too-many-units": (("runs = 3", "runs = 100000", "params = { alpha = 0.5 }",
                                 "params = { alpha = 0.5 }\n[[filter]]\nname = \"pf\"\ngrid = { n_particles = ["
                                 + ", ".join(str(100 + i) for i in range(100)) + "] }"),
                                r"c\.toml:16: n_particles: 101 filter configurations x 100000 runs, more than a "
                                r"campaign may hold \(10000000 units\)"),
    "campaign-too-many-units-datasets": (("runs = 3", "runs = 100000", "params = { alpha = 0.5 }",
                                          "params = { alpha = 0.5 }\n[[filter]]\nname = \"pf\"\ngrid = { n_particles "
                                          "= [" + ", ".join(str(100 + i) for i in range(51)) + "] }\n[[dataset]]\n"
                                          "id = \"sim/auv-sonar\"\nparams = { steps = 30 }"),
                                         r"c\.toml:3: runs: 104 configurations x 100000 runs = 10400000 units, more "
                                         r"than a campaign may hold \(10000000\)"),
}
register(*STORES, *CAMPAIGN_FILES, "campaign-binary-file", "campaign-out-300-chars", "campaign-disk-full",
         "campaign-disk-too-small", "campaign-grid-no-flush-per-config", "campaign-export-reuses-data-dir",
         "leaderboard-source-column", "campaign-dask-hint")


def _copy(store, tmp_path):
    d, rows = store
    out = tmp_path / "out"
    shutil.copytree(d / "out", out)
    return d / "c.toml", out, next(p for p in (out / "units").iterdir()), rows


def _edit_digit(path: Path) -> None:
    """Change one digit of the record's pos_rmse (the JSON stays valid, the record plausible)."""
    text = path.read_text()
    m = re.search(r'"pos_rmse": (\d)\.(\d)', text)
    digit = str((int(m.group(2)) + 1) % 10)
    path.write_text(text[:m.start(2)] + digit + text[m.end(2):])
    assert path.read_text() != text


@pytest.mark.parametrize("case", STORES)
def test_damaged_store_refused_by_readers_and_repaired_by_run(case, store, tmp_path):  # noqa: F811
    c, out, unit, rows = _copy(store, tmp_path)
    if case == "store-edited-metric":
        _edit_digit(unit / "1.json")
        problem = rf"{unit / '1.json'}: content differs from the checksum it holds"
        repair = f"recomputed 1 damaged unit: {unit / '1.json'}: "
    elif case == "store-legacy-record-edited":
        for p in unit.glob("[0-9]*.json"):  # as written before records held their checksum
            rec = json.loads(p.read_text())
            del rec["record_sha256"]
            p.write_text(json.dumps(rec, indent=1))
        assert_ok(["leaderboard", out])  # old stores are still read ...
        assert _rows(out) == rows
        _edit_digit(unit / "1.json")  # ... and a metric that disagrees with the table is refused
        problem = rf"{unit / '1.json'}: pos_rmse [0-9.]+ disagrees with its table"
        repair = f"recomputed 1 damaged unit: {unit / '1.json'}: pos_rmse"
    elif case == "store-unit-dir-is-file":
        shutil.rmtree(unit)
        unit.write_text("not a directory")
        problem = rf"{unit}: not a directory \(the units of configuration {unit.name} belong there\)"
        repair = None
    elif case == "store-unit-dir-missing":
        shutil.rmtree(unit)
        problem = (rf"{unit}: missing: configuration sim/auv-sonar sonar ukf, listed in {out / 'configs.json'}, "
                   r"has no units directory")
        repair = f"recomputed 1 missing configuration: {unit}: missing (listed in {out / 'configs.json'})"
    elif case == "store-config-json-removed":
        (unit / "config.json").unlink()
        problem = rf"{unit / 'config.json'}: missing; run `replay campaign run` on its campaign file again"
        repair = f"rewrote 1 damaged configuration file: {unit / 'config.json'}: missing"
    else:
        index = out / "configs.json"
        index.write_text(index.read_text().replace('"alpha": 0.5', '"alpha": 0.25'))
        problem = rf"{index}: content differs from the checksum it holds"
        repair = f"rewrote 1 damaged configuration file: {index}: content differs"
    for args in (["leaderboard", out], ["report", out]):
        assert_refused(args, problem)
    if repair is None:  # refused by the campaign too, naming it, before any work
        assert_refused(["campaign", "run", c, "-o", out, "-w", "1", "-q"], problem)
        assert unit.read_text() == "not a directory"
        return
    res = assert_ok(["campaign", "run", c, "-o", out, "-w", "1", "-q"])
    assert repair in res.stdout, res.stdout
    assert _rows(out) == rows
    assert_ok(["leaderboard", out])


def test_records_are_sealed_over_their_canonical_json(store):  # noqa: F811
    from replay.campaign import records

    d, _ = store
    for p in (d / "out" / "units").glob("*/[0-9]*.json"):
        rec = json.loads(p.read_text())
        assert records.problem(p, rec) is None and len(rec[records.KEY]) == 64
        rec["metrics"]["ate"] *= 2
        assert "content differs from the checksum" in records.problem(p, rec)


@pytest.mark.parametrize("case", list(CAMPAIGN_FILES))
def test_campaign_values_refused_by_their_declarations_before_work(case, tmp_path):
    edits, match = CAMPAIGN_FILES[case]
    text = CAMPAIGN
    for old, new in zip(edits[::2], edits[1::2]):
        assert old in text
        text = text.replace(old, new, 1)
    path = tmp_path / "c.toml"
    path.write_text(text)
    assert_refused(["campaign", "run", path, "-o", tmp_path / "out"], match)
    assert not (tmp_path / "out").exists()


def test_binary_campaign_file_and_long_out_refused(tmp_path):
    path = tmp_path / "c.toml"
    path.write_bytes(bytes(range(256)) * 4)
    assert_refused(["campaign", "run", path, "-o", tmp_path / "out"],
                   rf"{path}: not a campaign file \(not UTF-8 text: byte 128\)")
    path.write_text(CAMPAIGN)
    out = tmp_path / ("o" * 300)
    for args in (["campaign", "run", path], ["leaderboard", tmp_path], ["report", tmp_path]):
        assert_refused([*args, "-o", out], r"--out .*: a name in it is 300 bytes long \(file systems allow 255\)")


def test_full_disk_stops_in_one_line_with_the_stored_units_intact(store, tmp_path, monkeypatch):  # noqa: F811
    from replay.campaign.store import Store

    d, rows = store
    out = tmp_path / "out"
    real = os.fsync

    def fsync(fd):
        if os.path.basename(os.readlink(f"/proc/self/fd/{fd}")).startswith(".2.json."):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    assert_refused(["campaign", "run", d / "c.toml", "-o", out, "-w", "1", "-q"],
                   rf"cannot write \(No space left on device\); the units stored in {out} before are intact")
    monkeypatch.setattr(os, "fsync", real)
    h = next((out / "units").iterdir()).name
    good, bad = Store(out).scan(h)
    assert sorted(good) == [0, 1] and not bad
    assert not list(out.rglob("*.tmp"))
    res = assert_ok(["campaign", "run", d / "c.toml", "-o", out, "-w", "1", "-q"])
    assert "1 units computed, 0 failed" in res.stdout
    assert _rows(out) == rows


def test_disk_too_small_for_the_units_refused_before_work(store, tmp_path, monkeypatch):  # noqa: F811
    d, _ = store
    out = tmp_path / "out"
    monkeypatch.setattr(os, "statvfs", lambda p: SimpleNamespace(f_flag=0, f_bfree=2, f_bavail=2, f_frsize=4096))
    assert_refused(["campaign", "run", d / "c.toml", "-o", out, "-w", "1", "-q"],
                   rf"--out {out}: not enough space on the file system of {tmp_path} \(8192 bytes free, at "
                   r"least 1048576 needed\)")  # replay eval's output check (1 MB) comes before the units' estimate
    from replay.util import staging

    monkeypatch.setattr(staging, "MIN_FREE", 4096)  # that one passed: the units' own estimate refuses
    assert_refused(["campaign", "run", d / "c.toml", "-o", out, "-w", "1", "-q"],
                   rf"--out {out}: not enough space on the file system of {out} \(8192 bytes free, at least "
                   r"24576 needed\)")
    assert not list((out / "units").rglob("*.json*"))


def test_grid_writes_one_index_not_a_flushed_file_per_configuration(tmp_path, monkeypatch):
    from replay.campaign import execute, spec
    from replay.campaign.store import Store

    grid = ", ".join(f"{0.1 + 0.02 * i:.2f}" for i in range(40))
    path = tmp_path / "g.toml"
    path.write_text(CAMPAIGN.replace("params = { alpha = 0.5 }", f"grid = {{ alpha = [{grid}] }}"))
    c = spec.load(path)
    assert len(c.configs) == 40
    synced, real = [], os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: (synced.append(os.readlink(f"/proc/self/fd/{fd}")), real(fd))[1])
    jobs = execute.plan(c, Store(tmp_path / "out"))
    assert len(jobs) == 40 and len(synced) == 2  # configs.json and units/
    assert not list((tmp_path / "out" / "units").glob("*/config.json"))
    monkeypatch.setattr(execute, "PLAN_PROGRESS", 10)
    from io import StringIO

    stream = StringIO()
    counts = execute.run(c, tmp_path / "out", execute.RunOptions(workers=1, limit=1, progress_stream=stream))
    assert "campaign: checking stored units: 40/40 configurations" in stream.getvalue()
    assert counts["done"] == 3 and len(list((tmp_path / "out" / "units").glob("*/config.json"))) == 1
    listed = json.loads((tmp_path / "out" / "configs.json").read_text())["configs"]
    assert sorted(listed) == sorted(p.name for p in (tmp_path / "out" / "units").iterdir())


def test_campaign_export_reuses_the_data_dir_it_ran_with(bohai_dir, tmp_path):
    path = tmp_path / "b.toml"
    path.write_text(f'[campaign]\nname = "b"\nruns = 1\ndata_dir = "{bohai_dir.parent}"\n'
                    '[[dataset]]\nid = "bohai/20220822_0_6"\nfirst = 200\n[[filter]]\nname = "ekf"\n')
    out = tmp_path / "out"
    assert_ok(["campaign", "run", path, "-o", out, "-w", "1", "-q"])
    assert json.loads((out / "configs.json").read_text())["data_dirs"] == {
        "bohai/20220822_0_6": str(bohai_dir.parent.resolve())}
    res = assert_ok(["export", out, "--mcap", tmp_path / "b.mcap", "-q"])  # no --data-dir
    assert f"wrote {tmp_path / 'b.mcap'}" in res.stdout and (tmp_path / "b.mcap").stat().st_size > 0


def test_merged_leaderboard_names_each_row_source(store, tmp_path):  # noqa: F811
    d, _ = store
    ev = tmp_path / "ev"
    assert_ok(["eval", "sim/auv-sonar", "-f", "ukf", "-p", "ukf.alpha=0.5", "--runs", "2", "--seed", "1",
               "--dataset-param", "steps=20", "-o", ev])
    merged = tmp_path / "m.csv"
    res = assert_ok(["leaderboard", d / "out", ev, "-o", merged])
    assert res.stdout.splitlines()[0].split()[0] == "source"
    rows = list(csv.DictReader(open(merged)))
    assert list(rows[0])[0] == "source"
    assert [(r["source"], r["runs"]) for r in rows] == [(str(d / "out"), "3"), (str(ev), "2")]


def test_missing_dask_hint_names_the_checkout_install(monkeypatch):
    import builtins

    from replay.campaign import execute
    from replay.util.errors import ReplayError

    real = builtins.__import__
    monkeypatch.setattr(builtins, "__import__", lambda name, *a, **k: (_ for _ in ()).throw(ImportError(name))
                        if name == "distributed" else real(name, *a, **k))
    with pytest.raises(ReplayError, match=r'pip install -e "\.\[campaign\]"'):
        with execute._dask(None, 1, 1.0):
            pass
