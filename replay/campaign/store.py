"""The result directory of a campaign; units stored atomically and durably, checked when read.

Layout of ``OUT``::

    campaign.toml                      copy of the campaign file last run here
    campaign.lock                      held (flock) by the campaign process writing here; its pid
    configs.json                       every configuration and the data_dir of each dataset
                                       (:mod:`replay.campaign.index`), with its SHA-256
    units/<config_hash>/config.json    the configuration (dataset, task, filter, parameters, seed, ...)
    units/<config_hash>/<run>.parquet  per-step table: k, t, x<i>, P<ii>, ref_<axis>, err_<axis>,
                                       err_<angle>, nees, nis, nis_dof
    units/<config_hash>/<run>.json     status (done/failed), metrics or error, version, the
                                       table's rows, columns, size and SHA-256, and the SHA-256
                                       of the record itself (:mod:`.records`) — written last
    leaderboard.csv, paired.csv        summaries (replay.campaign.board)

A unit counts as stored when its ``.json`` exists. Every file is written to a
temporary name in the same directory and renamed into place (``os.replace`` is
atomic), the table before the record; each record (and ``config.json``) is
flushed to disk (``fsync``) before its rename, and the directory after each job (a job's
units are written side by side by a few threads, whose flushes share the journal's commits).
Tables are not flushed one by one (a flush costs 1–8 ms on this project's
machine, as much as computing a cheap unit): the record holds the table's size
and SHA-256, so a table that a power loss left incomplete is found damaged and
computed again. A run killed at any instant leaves at worst a stray ``*.tmp`` or
a table without record: the unit is computed again.

A stored unit is **checked** whenever it is read (:meth:`Store.scan`): a record
that is empty, not JSON, not a unit record or not what its checksum says, a table that is missing, empty,
truncated (no Parquet footer), of other columns or rows than its record says,
or whose bytes differ from the recorded checksum, makes the unit *damaged*.
``replay campaign run`` computes damaged units again (and says which);
``replay leaderboard`` and ``replay report`` refuse in one line naming the file
(:meth:`Store.records`). Records written before the table was described in them
are checked for the columns the leaderboard reads and for the row count of the
configuration's other units; records without their own checksum, for the metrics the
table determines (:func:`.records.legacy_problem`).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import threading
from collections import Counter
from pathlib import Path

import numpy as np

from replay.util.version import __version__
from replay.util.errors import ReplayError

from . import records as sealing, index
from .encode import (
    SUMMARY_COLUMNS,
    describe,
    footer as _footer,
    pack,
    parquet_bytes,  # noqa: F401 (re-exported)
    summary_columns,
    to_arrow,
    to_numpy,
)
from replay.util.files import json_default, sync_dir, write_bytes, write_json
from replay.scoring.record import DONE, RunRecord
from replay.run.pipeline import config_hash as hash_of
from concurrent.futures import ThreadPoolExecutor

RUN_FILE = re.compile(r"^(\d+)\.json$")
LEGACY_COLUMNS = ("k", "t", "nees", "nis", "nis_dof")  # read by the leaderboard (replay.scoring.summary)
KEPT_BYTES = 64 << 20  # at most this much of those columns kept in memory by a Store that wrote them
WRITERS = 8  # threads writing a job's units (Store.write_job)
RERUN_HINT = "run `replay campaign run` on its campaign file again to recompute it"


class Store:
    def __init__(self, out):
        self.out = Path(out)
        self.units = self.out / "units"
        self._kept, self._kept_bytes = {}, 0  # (config_hash, run) -> (table SHA-256, summary columns)
        self._lock = threading.Lock()

    # ---- reading, with checks ------------------------------------------------------------
    def scan(self, config_hash: str) -> tuple[dict[int, RunRecord], dict[int, str]]:
        """Every stored unit of a configuration, checked: ``({run: record}, {run: problem})``,
        a problem being one line naming the damaged file and what is wrong with it."""
        d = self.units / config_hash
        good, bad = {}, {}
        if not d.is_dir():
            return good, bad
        legacy = {}
        for name in sorted(os.listdir(d)):
            m = RUN_FILE.match(name)
            if not m:
                continue
            run = int(m.group(1))
            rec, problem = self._read_record(d / name, run, config_hash)
            if problem is None and rec.done:
                problem, rows = self._check_table(d / f"{run}.parquet", rec.table)
                if problem is None and rows is not None:
                    legacy[run] = rows
                if problem is None:  # a record without its checksum: its metrics against the table
                    problem = sealing.legacy_problem(d / name, rec, lambda cols: self.series(config_hash, run, cols))
            if problem is None:
                good[run] = rec
            else:
                bad[run] = problem
        if legacy:  # records without a table description: rows as the configuration's other units
            expected = Counter(legacy.values()).most_common(1)[0][0]
            described = [r.table["rows"] for r in good.values() if isinstance(r.table, dict)]
            expected = described[0] if described else expected
            for run, rows in legacy.items():
                if rows != expected:
                    bad[run] = f"{d / f'{run}.parquet'}: {rows} rows, the configuration's other units have {expected}"
                    del good[run]
        return good, bad

    @staticmethod
    def _read_record(path: Path, run: int, config_hash: str) -> tuple[RunRecord | None, str | None]:
        """(record, None) of an intact unit record, else (None, one line naming ``path``)."""
        try:
            raw = path.read_bytes()
        except OSError as err:
            return None, f"{path}: cannot read the unit record ({err.strerror})"
        if not raw:
            return None, f"{path}: zero-length unit record"
        try:
            rec = json.loads(raw)
        except (ValueError, UnicodeDecodeError) as err:
            return None, f"{path}: unit record is not valid JSON ({str(err).splitlines()[0]})"
        if not isinstance(rec, dict):
            return None, f"{path}: unit record is not a JSON object"
        if rec.get("run") != run or isinstance(rec.get("run"), bool):
            return None, f"{path}: unit record is of run {rec.get('run')!r}, not {run}"
        if rec.get("status") not in ("done", "failed"):
            return None, f"{path}: unit record has status {rec.get('status')!r} (expected done or failed)"
        if rec.get("config_hash", config_hash) != config_hash:
            return None, f"{path}: unit record belongs to configuration {rec.get('config_hash')!r}"
        if rec["status"] == "done" and not isinstance(rec.get("metrics"), dict):
            return None, f"{path}: unit record has no metrics"
        sealed = sealing.problem(path, rec)
        return (None, sealed) if sealed else (RunRecord.from_dict(rec), None)

    @staticmethod
    def _check_table(path: Path, table):
        """(problem or None, rows to compare across units when the record does not describe the table)."""
        try:
            size = path.stat().st_size
        except OSError:
            return f"{path}: missing (its record says the run is done)", None
        if size == 0:
            return f"{path}: zero-length table", None
        described = isinstance(table, dict) and isinstance(table.get("bytes"), int)
        if described and size == table["bytes"]:
            try:
                if hashlib.sha256(path.read_bytes()).hexdigest() == table.get("sha256"):
                    return None, None  # the bytes its record describes
            except OSError as err:
                return f"{path}: cannot read ({err.strerror})", None
        try:  # what is wrong with it
            rows, names = _footer(str(path))
        except ValueError as err:
            if described and size < table["bytes"]:
                return f"{path}: truncated ({size} bytes, its record says {table['bytes']})", None
            return f"{path}: not a readable Parquet table ({err})", None
        expected = list(table.get("columns", [])) if described else list(LEGACY_COLUMNS)
        missing = [c for c in expected if c not in names]
        if missing or (described and names != expected):
            extra = [c for c in names if c not in expected]
            return (
                f"{path}: columns differ from the unit's (missing {', '.join(missing) or 'none'}; "
                f"unexpected {', '.join(extra) or 'none'})"
            ), None
        if not described:
            return None, rows
        if rows != table.get("rows"):
            return f"{path}: {rows} rows, its record says {table.get('rows')}", None
        if size != table["bytes"]:
            return f"{path}: {size} bytes, its record says {table['bytes']}", None
        return f"{path}: content differs from the checksum in its record", None

    def damaged(self, config_hash: str) -> dict[int, str]:
        """{run: problem} of the configuration's damaged units."""
        return self.scan(config_hash)[1]

    def stored_runs(self, config_hash: str, include_failed: bool = True) -> set[int]:
        """Runs stored intact (damaged units are not stored: they are computed again)."""
        good = self.scan(config_hash)[0]
        return {run for run, rec in good.items() if include_failed or rec.done}

    def records(self, config_hash: str) -> list[RunRecord]:
        """Stored unit records of a configuration, in run order; a damaged unit raises a
        :class:`ReplayError` naming its file."""
        good, bad = self.scan(config_hash)
        if bad:
            raise ReplayError(f"{bad[min(bad)]}; {RERUN_HINT}")
        return [good[run] for run in sorted(good)]

    def read_config(self, config_hash: str) -> tuple[dict | None, str | None]:
        """(config, None) or (None, problem): ``config.json`` must be a JSON object whose
        configuration hash is its directory's name."""
        path = self.units / config_hash / "config.json"
        try:
            raw = path.read_bytes()
        except FileNotFoundError:
            return None, f"{path}: missing"
        except OSError as err:
            return None, f"{path}: cannot read ({err.strerror})"
        try:
            cfg = json.loads(raw)
        except (ValueError, UnicodeDecodeError):
            return None, f"{path}: {'zero-length' if not raw.strip() else 'not valid JSON'}"
        if not isinstance(cfg, dict):
            return None, f"{path}: not a JSON object"
        try:
            ok = hash_of(cfg) == config_hash
        except (TypeError, ValueError):
            ok = False
        if not ok:
            return None, f"{path}: does not hold configuration {config_hash} (edited or damaged)"
        return cfg, None

    def configs(self, skip=(), listed: dict | None = None):
        """(config_hash, config) of every stored configuration but those in ``skip``: those the
        index names (:mod:`.index`) and those of the ``units/`` directories. A damaged index or
        ``config.json`` (or unit records without one), an entry of ``units/`` that is not a
        directory, or a configuration of the index without its directory raises a
        :class:`ReplayError` naming it. ``listed``: the index's configurations, when read already."""
        problem = None
        if listed is None:
            listed, _, problem = index.read(self.out)
        if problem is not None:
            raise ReplayError(f"{problem}; run `replay campaign run` on its campaign file again to rewrite it")
        entries = sorted(self.units.iterdir()) if self.units.is_dir() else []
        for d in entries:
            if not d.is_dir() and not d.name.startswith("."):
                raise ReplayError(
                    f"{d}: not a directory (the units of configuration {d.name} belong there); "
                    "move it away and run `replay campaign run` on its campaign file again"
                )
        for h, cfg in listed.items():
            if h not in skip and not (self.units / h).is_dir():
                raise ReplayError(
                    f"{self.units / h}: missing: configuration {index.describe(cfg)}, listed in "
                    f"{self.out / index.NAME}, has no units directory; {RERUN_HINT}"
                )
        out = []
        for d in entries:
            if not d.is_dir() or d.name in skip:
                continue
            cfg, problem = self.read_config(d.name)
            if problem is None:
                out.append((d.name, cfg))
            elif (
                problem.endswith(": missing")
                and d.name in listed
                and not any(RUN_FILE.match(p.name) for p in d.iterdir())
            ):
                out.append((d.name, listed[d.name]))  # no units yet: config.json comes with the first
            elif (d / "config.json").exists() or any(RUN_FILE.match(p.name) for p in d.iterdir()):
                raise ReplayError(f"{problem}; run `replay campaign run` on its campaign file again to rewrite it")
        return out

    def data_dirs(self) -> dict:
        """{dataset id: the ``data_dir`` the campaign ran it with} (empty for an older store)."""
        return index.read(self.out)[1]

    def series(self, config_hash: str, run: int, columns=None, sha256: str | None = None):
        """The per-step table of a unit as a dict of numpy arrays (``columns``: those only).

        ``sha256``: the checksum of the table that its record holds and :meth:`scan` found on
        disk; when this Store wrote that very table, the columns it kept of it are returned
        without reading the file (the values the file holds, bit for bit)."""
        # lazy: start-up, pyarrow measured ~180 ms, needed only to write or read a table
        import pyarrow as pa  # noqa: PLC0415
        import pyarrow.parquet as pq  # noqa: PLC0415

        kept = self._kept.get((config_hash, run))
        if (
            sha256 is not None
            and columns is not None
            and kept is not None
            and kept[0] == sha256
            and all(c in kept[1] for c in columns)
        ):
            return {c: kept[1][c] for c in columns}
        path = self.units / config_hash / f"{run}.parquet"
        try:
            t = pq.ParquetFile(path).read(columns=columns)
        except (pa.ArrowException, OSError, ValueError) as err:
            raise ReplayError(
                f"{path}: unreadable unit table ({str(err).splitlines()[0] if str(err) else ''}); {RERUN_HINT}"
            ) from None
        return {name: to_numpy(t.column(name)) for name in t.column_names}

    # ---- writing -----------------------------------------------------------------------
    def save_config(self, config_hash: str, config: dict) -> str | None:
        """Write ``config.json`` unless an intact one is there; returns the problem of the
        one it replaced (damaged), else None."""
        d = self.units / config_hash
        new = not d.is_dir()
        d.mkdir(parents=True, exist_ok=True)
        if new:
            sync_dir(self.units)
        _, problem = self.read_config(config_hash)
        if problem is not None:
            write_json(d / "config.json", config)
            sync_dir(d)
            return None if problem.endswith(": missing") else problem
        return None

    def write(self, config_hash: str, result: RunRecord, sync: bool = True) -> None:
        """Store one unit: the per-step table (done units), then the record that marks it stored
        and describes the table (rows, columns, size, SHA-256); ``sync``: also flush the
        directory (:meth:`write_job` does it once per job).

        The table comes as ``result.parquet`` (bytes from :func:`pack`, encoded by the
        worker) or as ``result.series`` (a dict of arrays, encoded here)."""
        d = self.units / config_hash
        run = result.run
        record = result.to_dict() | {"key": f"{config_hash}/{run}", "config_hash": config_hash, "version": __version__}
        if result.status == DONE:
            data = result.parquet if result.parquet is not None else parquet_bytes(result.series)
            record["table"] = describe(data)
            write_bytes(d / f"{run}.parquet", data, sync=False)  # its record's checksum vouches for it
            kept = result.leaderboard_columns
            self._keep(
                config_hash,
                run,
                record["table"]["sha256"],
                kept if kept is not None else summary_columns(result.series or {}),
            )
        write_json(d / f"{run}.json", sealing.seal(record, json_default))
        if sync:
            sync_dir(d)

    def _keep(self, config_hash: str, run: int, sha256: str, columns: dict) -> None:
        """Keep the leaderboard's columns of a table written here (see :meth:`series`), up to
        :data:`KEPT_BYTES` in all."""
        size = sum(v.nbytes for v in columns.values())
        with self._lock:  # write_job's threads
            old = self._kept.pop((config_hash, run), None)
            self._kept_bytes -= sum(v.nbytes for v in old[1].values()) if old else 0
            if self._kept_bytes + size <= KEPT_BYTES:
                self._kept[(config_hash, run)] = (sha256, columns)
                self._kept_bytes += size

    def write_job(self, config_hash: str, results: list[RunRecord]) -> None:
        """Store a job's units, then flush the directory once. The units are written by a few
        threads: their flushes then share the file system's journal commits (25 records one
        after the other: 6-100 ms; side by side: a tenth of that)."""
        with ThreadPoolExecutor(max(1, min(WRITERS, len(results)))) as pool:
            for _ in pool.map(lambda res: self.write(config_hash, res, sync=False), results):
                pass
        sync_dir(self.units / config_hash)
