"""The run record (replay/scoring/record.py): one dataclass from the pipeline to the campaign store and
back, with the stored JSON byte for byte what replay wrote before the record was a dataclass."""

import json
import pickle
import shutil
from pathlib import Path

import numpy as np

from replay.campaign import board
from replay.campaign.store import Store
from replay.run.failures import failed
from replay.run.pipeline import Config, run_block
from replay.scoring.record import RunRecord

# a campaign directory written by replay at commit af83599 (runs were dicts then): 3 done units of ekf on
# sim/auv-sonar (steps = 12), a failed unit written by run.failures.failed and one of a worker lost
# (no traceback), its leaderboard.csv and paired.csv written by that version
MAIN = Path(__file__).parent / "fixtures" / "campaign_af83599"
H = "d88a2011adee9cdd"

FULL = {  # every key a record written to a file can hold, in the order a store writes them
    "run": 2,
    "status": "done",
    "metrics": {"pos_rmse": 1.5, "diverged": False, "diverged_at": None, "seconds": 0.01},
    "content_checked": False,
    "reference_input": "pose.position read from /reference/pose, the reference's topic",
    "reference": "fed sensor",
    "reference_shares": "gps.position (the same topic /fix)",
    "unconstrained": "yaw: nothing measures it",
    "rejected": {"gps.position": 3},
    "note": "recorded:slam: 120 poses associated",
    "key": "h/2",
    "config_hash": "h",
    "version": "0.1.0",
    "table": {"rows": 4, "columns": ["k", "t"], "bytes": 100, "sha256": "0" * 64},
    "record_sha256": "1" * 64,
}


def test_a_record_goes_to_a_dict_and_back_keeping_its_keys_and_their_order():
    rec = RunRecord.from_dict(FULL)
    assert rec.run == 2 and rec.done and not rec.diverged and rec.rejected == {"gps.position": 3}
    assert rec.table_sha256 == "0" * 64 and rec.metric("pos_rmse") == 1.5 and np.isnan(rec.metric("ate"))
    assert list(rec.to_dict().items()) == list(FULL.items())
    # a key this version does not know (another version's record): kept, written back after the others
    newer = {**FULL, "future": [1, 2]}
    back = RunRecord.from_dict(newer)
    assert back.extra == {"future": [1, 2]} and list(back.to_dict().items()) == list(newer.items())
    # what is in memory only never goes into the file's object
    mem = RunRecord(0, "done", {"diverged": True}, {"k": np.arange(3)}, problem=object(), parquet=b"PAR1")
    assert mem.to_dict() == {"run": 0, "status": "done", "metrics": {"diverged": True}} and mem.diverged


def test_a_failed_record_as_the_pipeline_and_a_lost_worker_write_it():
    try:
        raise KeyError("nope")
    except KeyError as err:
        rec = failed(3, err)
    assert list(rec.to_dict()) == ["run", "status", "error", "traceback"] and rec.error == "KeyError: 'nope'"
    assert not rec.done and not rec.diverged and rec.metrics is None
    lost = RunRecord(4, "failed", error="KilledWorker: lost")
    assert lost.to_dict() == {"run": 4, "status": "failed", "error": "KilledWorker: lost"}


def test_records_cross_processes_pickled():
    rec = RunRecord(1, "done", {"diverged": False}, parquet=b"PAR1", leaderboard_columns={"nees": np.ones(3)})
    back = pickle.loads(pickle.dumps(rec))
    assert back.run == 1 and back.parquet == b"PAR1" and np.array_equal(back.leaderboard_columns["nees"], np.ones(3))


def test_units_written_by_the_dict_version_read_and_write_back_byte_for_byte():
    paths = sorted((MAIN / "units" / H).glob("[0-9]*.json"))
    assert len(paths) == 5
    for p in paths:
        raw = p.read_bytes()
        rec = RunRecord.from_dict(json.loads(raw))
        assert rec.extra == {} and json.dumps(rec.to_dict(), indent=1).encode() == raw, p.name
    recs = Store(MAIN).records(H)  # checked (checksums, tables) as any stored unit
    assert [(r.run, r.status) for r in recs] == [(0, "done"), (1, "done"), (2, "done"), (3, "failed"), (4, "failed")]
    assert recs[3].error == "KeyError: 'nope'" and recs[4].traceback is None and recs[0].reference == "simulated truth"


def test_the_leaderboard_of_the_dict_version_s_store_is_the_same_file(tmp_path):
    out = tmp_path / "c"
    shutil.copytree(MAIN, out)  # never written inside an input
    board.summarise(out)
    for name in ("leaderboard.csv", "paired.csv"):
        assert (out / name).read_bytes() == (MAIN / name).read_bytes(), name


def test_a_store_writes_what_the_dict_version_wrote(tmp_path):
    """The same campaign computed now: every record the same keys in the same order and the same
    values, but the timings (and so the checksum), and the tables the same bytes."""
    cfg = json.loads((MAIN / "units" / H / "config.json").read_text())
    recs = run_block(Config(**cfg), [0, 1, 2])
    s = Store(tmp_path / "c")
    (s.units / H).mkdir(parents=True)
    s.write_job(H, recs)
    timing = ("seconds", "us_per_step")
    for run in (0, 1, 2):
        new, old = (json.loads((d / "units" / H / f"{run}.json").read_text()) for d in (s.out, MAIN))
        assert list(new) == list(old) and new["table"] == old["table"]
        assert {k: v for k, v in new["metrics"].items() if k not in timing} == {
            k: v for k, v in old["metrics"].items() if k not in timing
        }
        assert (s.units / H / f"{run}.parquet").read_bytes() == (MAIN / "units" / H / f"{run}.parquet").read_bytes()
