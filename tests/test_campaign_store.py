"""What a campaign keeps in memory and how it schedules give the files it would give without.

* the leaderboard columns a :class:`Store` keeps of the tables it wrote are the file's
  values bit for bit, and are used only for the table its record describes;
* the leaderboard written at the end of ``campaign run`` is the one a fresh read of the
  directory gives (``replay leaderboard``);
* the per-step tables are plain-encoded Parquet;
* a local pool gets the heaviest jobs first.
"""
import csv
from contextlib import contextmanager

import numpy as np
import pyarrow.parquet as pq
import pytest

from replay.campaign import board, execute, spec, store
from replay.campaign.store import Store, pack
from replay.run.pipeline import config_hash
from replay.scoring.record import RunRecord

from test_campaign import SMALL, write


def _result(run, n=40, seed=0):
    rng = np.random.default_rng(seed + run)
    nees = rng.chisquare(3, n)
    nees[::7] = np.nan
    series = {"k": np.arange(n), "t": np.linspace(0.0, 1.0, n), "x0": rng.normal(size=n), "nees": nees,
              "nis": rng.chisquare(2, n), "nis_dof": np.full(n, 2)}
    return RunRecord(run, "done", {"pos_rmse": 1.0 + run, "diverged": False}, series)


def test_kept_columns_are_the_files_values(tmp_path):
    writer = Store(tmp_path / "o")
    (writer.units / "h").mkdir(parents=True)
    writer.write_job("h", pack([_result(r) for r in range(3)]))
    reader = Store(tmp_path / "o")  # nothing kept: reads the files
    cols = ["nees", "nis", "nis_dof"]
    for rec in reader.records("h"):
        sha = rec.table["sha256"]
        kept, disk = writer.series("h", rec.run, cols, sha), reader.series("h", rec.run, cols, sha)
        assert list(kept) == cols and kept["nees"] is writer._kept[("h", rec.run)][1]["nees"]
        for c in cols:
            assert kept[c].dtype == disk[c].dtype and np.array_equal(kept[c].view(np.uint8), disk[c].view(np.uint8))
    # another table than the one kept (rewritten since), or columns not kept: the file
    other = writer.series("h", 0, cols, "0" * 64)
    assert other["nees"] is not writer._kept[("h", 0)][1]["nees"]
    assert np.array_equal(other["nees"], reader.series("h", 0, cols)["nees"], equal_nan=True)
    assert "x0" in writer.series("h", 0, ["x0", "nees"], reader.records("h")[0].table["sha256"])


def test_kept_columns_are_bounded(tmp_path, monkeypatch):
    monkeypatch.setattr(store, "KEPT_BYTES", 2 * 40 * 8 * 3)  # two units' columns
    s = Store(tmp_path / "o")
    (s.units / "h").mkdir(parents=True)
    for r in range(4):
        s.write("h", pack([_result(r)])[0])
    assert sorted(s._kept) == [("h", 0), ("h", 1)] and s._kept_bytes == 2 * 40 * 8 * 3
    s.write("h", pack([_result(0, seed=9)])[0])  # rewritten: its old columns let go, the new ones kept
    sha = {r.run: r.table["sha256"] for r in s.records("h")}
    assert sorted(s._kept) == [("h", 0), ("h", 1)] and s._kept_bytes == 2 * 40 * 8 * 3
    assert s._kept[("h", 0)][0] == sha[0] and len(sha) == 4


def test_tables_are_plain_encoded(tmp_path):
    s = Store(tmp_path / "o")
    (s.units / "h").mkdir(parents=True)
    s.write("h", pack([_result(0)])[0])
    meta = pq.ParquetFile(s.units / "h" / "0.parquet").metadata.row_group(0)
    encodings = {e for i in range(meta.num_columns) for e in meta.column(i).encodings}
    assert "PLAIN" in encodings and not any("DICTIONARY" in e for e in encodings)


def _board_bytes(out):
    return (out / "leaderboard.csv").read_bytes(), (out / "paired.csv").read_bytes()


def test_leaderboard_of_the_run_is_a_fresh_reads(tmp_path):
    plan = spec.load(write(tmp_path, SMALL))
    out = tmp_path / "out"
    execute.run(plan, out, execute.RunOptions(workers=1, quiet=True))  # summarised by the Store that wrote the units
    written = _board_bytes(out)
    board.summarise(out, [config_hash(c.as_dict()) for c in plan.configs])  # from the files
    assert _board_bytes(out) == written
    rows = list(csv.DictReader((out / "leaderboard.csv").read_text().splitlines()))
    assert len(rows) == 4 and all(r["anees_flag"] and r["runs"] == "6" for r in rows)


def test_a_pool_gets_the_heaviest_jobs_first(tmp_path, monkeypatch):
    order = []

    @contextmanager
    def fake_pool(workers, warm):
        assert not warm  # a campaign's jobs go to the pool as they are (only tune warms its kernels first)

        def run(jobs):
            for job in jobs:
                order.append((job.config["filter"], job.runs[0]))
                yield job, execute.execute_packed(job)
        yield run

    monkeypatch.setattr(execute, "_processes", fake_pool)
    plan = spec.load(write(tmp_path, SMALL))
    counts = execute.run(plan, tmp_path / "out", execute.RunOptions(workers=2, quiet=True))
    assert counts["backend"] == "processes(2)" and counts["done"] == 24
    assert order == [("pf", 0), ("pf", 3), ("ekf", 0), ("ekf", 3), ("ukf", 0), ("ukf", 3), ("ukf", 0), ("ukf", 3)]
    serial = tmp_path / "serial"
    execute.run(plan, serial, execute.RunOptions(workers=1, quiet=True))
    strip = lambda p: [{k: v for k, v in r.items() if k != "us_per_step"}
                       for r in csv.DictReader(p.read_text().splitlines())]
    assert strip(serial / "leaderboard.csv") == strip(tmp_path / "out" / "leaderboard.csv")


@pytest.mark.parametrize("kind", ["b", "O"])
def test_only_exact_round_trip_columns_are_kept(kind):
    v = np.array([True, False]) if kind == "b" else np.array(["a", "b"], dtype=object)
    assert store.summary_columns({"nees": v, "nis": np.array([1.0, 2.0])}) == {"nis": pytest.approx([1.0, 2.0])}
