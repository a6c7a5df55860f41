"""The result directory of a campaign; units stored atomically as they finish.

Layout of ``OUT``::

    campaign.toml                      copy of the campaign file last run here
    units/<config_hash>/config.json    the configuration (dataset, task, filter, parameters, seed, ...)
    units/<config_hash>/<run>.parquet  per-step table: k, t, x<i>, P<ii>, ref_<axis>, err_<axis>,
                                       err_<angle>, nees, nis, nis_dof
    units/<config_hash>/<run>.json     status (done/failed), metrics or error, version — written last
    leaderboard.csv, paired.csv        summaries (replay.campaign.board)

A unit counts as stored when its ``.json`` exists. Every file is written to a
temporary name in the same directory and renamed into place (``os.replace`` is
atomic), the table before the record, so a run killed at any instant leaves at
worst a stray ``*.tmp`` or a table without record: the unit is computed again.
"""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np

import replay

RUN_FILE = re.compile(r"^(\d+)\.json$")


def _atomic(path: Path, write) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    write(tmp)
    os.replace(tmp, path)


def write_json(path: Path, obj) -> None:
    _atomic(path, lambda p: p.write_text(json.dumps(obj, indent=1, default=_default)))


def _default(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def to_arrow(values):
    """A 1-D numpy array as a pyarrow Array. Integer and float columns go through their
    buffer: ``pa.array(ndarray)`` imports pandas (about 1 s), once in every worker and
    again in the main process when the leaderboard reads the tables back."""
    import pyarrow as pa

    v = np.ascontiguousarray(values)
    if v.ndim == 1 and v.dtype.kind in "iuf" and v.dtype.isnative:
        return pa.Array.from_buffers(pa.from_numpy_dtype(v.dtype), len(v), [None, pa.py_buffer(v)])
    return pa.array(v)


def to_numpy(column) -> np.ndarray:
    """A pyarrow (Chunked)Array as numpy; without pandas for integer/float columns without nulls."""
    import pyarrow as pa

    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    if arr.null_count == 0 and (pa.types.is_integer(arr.type) or pa.types.is_floating(arr.type)):
        dt = np.dtype(arr.type.to_pandas_dtype())
        return np.frombuffer(arr.buffers()[1], dt, count=len(arr), offset=arr.offset * dt.itemsize)
    return arr.to_numpy(zero_copy_only=False)


def parquet_bytes(series: dict) -> bytes:
    """A unit's per-step table (dict of equal-length arrays) as the bytes of a Parquet file."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    table = pa.Table.from_arrays([to_arrow(np.asarray(v)) for v in series.values()], names=list(series))
    pq.write_table(table, sink)
    return sink.getvalue().to_pybytes()


def pack(results: list[dict]) -> list[dict]:
    """Worker side: replace each result's ``series`` by its Parquet bytes (smaller to send,
    and the encoding runs in parallel instead of in the main process)."""
    return [{k: v for k, v in r.items() if k != "series"} | {"parquet": parquet_bytes(r["series"])}
            if "series" in r else r for r in results]


class Store:
    def __init__(self, out):
        self.out = Path(out)
        self.units = self.out / "units"

    def stored_runs(self, config_hash: str, include_failed: bool = True) -> set[int]:
        d = self.units / config_hash
        if not d.is_dir():
            return set()
        runs = set()
        for p in d.iterdir():
            m = RUN_FILE.match(p.name)
            if m and (include_failed or self._status(p) == "done"):
                runs.add(int(m.group(1)))
        return runs

    @staticmethod
    def _status(path: Path) -> str:
        try:
            return json.loads(path.read_text()).get("status", "failed")
        except (OSError, json.JSONDecodeError):
            return "failed"

    def save_config(self, config_hash: str, config: dict) -> None:
        d = self.units / config_hash
        d.mkdir(parents=True, exist_ok=True)
        if not (d / "config.json").exists():
            write_json(d / "config.json", config)

    def write(self, config_hash: str, result: dict) -> None:
        """Store one unit: the per-step table (done units), then the record that marks it stored.

        The table comes as ``result["parquet"]`` (bytes from :func:`pack`, encoded by the
        worker) or as ``result["series"]`` (a dict of arrays, encoded here)."""
        d = self.units / config_hash
        run = result["run"]
        record = {k: v for k, v in result.items() if k not in ("series", "parquet")}
        record.update(key=f"{config_hash}/{run}", config_hash=config_hash, version=replay.__version__)
        if result["status"] == "done":
            data = result["parquet"] if "parquet" in result else parquet_bytes(result["series"])
            _atomic(d / f"{run}.parquet", lambda p: p.write_bytes(data))
        write_json(d / f"{run}.json", record)

    def configs(self):
        """(config_hash, config) of every stored configuration."""
        if not self.units.is_dir():
            return []
        out = []
        for d in sorted(self.units.iterdir()):
            if (d / "config.json").is_file():
                out.append((d.name, json.loads((d / "config.json").read_text())))
        return out

    def records(self, config_hash: str) -> list[dict]:
        """Stored unit records of a configuration, in run order."""
        d = self.units / config_hash
        recs = []
        for run in sorted(self.stored_runs(config_hash)):
            try:
                recs.append(json.loads((d / f"{run}.json").read_text()))
            except (OSError, json.JSONDecodeError):
                continue
        return recs

    def series(self, config_hash: str, run: int, columns=None):
        """The per-step table of a unit as a dict of numpy arrays."""
        import pyarrow.parquet as pq

        t = pq.ParquetFile(self.units / config_hash / f"{run}.parquet").read(columns=columns)
        return {name: to_numpy(t.column(name)) for name in t.column_names}
