"""A unit's per-step table as the bytes of a Parquet file, and back, without pandas.

Workers encode (:func:`pack`: the Parquet bytes of each result's table, and the few
columns the leaderboard reads beside them, :func:`summary_columns`); the main process
describes the bytes in the unit's record (:func:`describe`: rows, columns, size,
SHA-256) and writes them (:mod:`replay.campaign.store`).
"""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np

from replay.scoring.record import RunRecord

SUMMARY_COLUMNS = ("nees", "nis", "nis_dof")  # the per-step columns the leaderboard reads


def to_arrow(values):
    """A 1-D numpy array as a pyarrow Array. Integer and float columns go through their
    buffer: ``pa.array(ndarray)`` imports pandas (about 1 s), once in every worker and
    again in the main process when the leaderboard reads the tables back."""
    # lazy: start-up, pyarrow measured ~180 ms, needed only to write or read a table
    import pyarrow as pa  # noqa: PLC0415

    v = np.ascontiguousarray(values)
    if v.ndim == 1 and v.dtype.kind in "iuf" and v.dtype.isnative:
        return pa.Array.from_buffers(pa.from_numpy_dtype(v.dtype), len(v), [None, pa.py_buffer(v)])
    return pa.array(v)


def to_numpy(column) -> np.ndarray:
    """A pyarrow (Chunked)Array as numpy; without pandas for integer/float columns without nulls."""
    # lazy: start-up, pyarrow measured ~180 ms, needed only to write or read a table
    import pyarrow as pa  # noqa: PLC0415

    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    if arr.null_count == 0 and (pa.types.is_integer(arr.type) or pa.types.is_floating(arr.type)):
        dt = np.dtype(arr.type.to_pandas_dtype())
        return np.frombuffer(arr.buffers()[1], dt, count=len(arr), offset=arr.offset * dt.itemsize)
    return arr.to_numpy(zero_copy_only=False)


def parquet_bytes(series: dict) -> bytes:
    """A unit's per-step table (dict of equal-length arrays) as the bytes of a Parquet file.
    Plain encoding: a dictionary of the float columns (distinct values) doubles the writing
    time and makes larger files."""
    # lazy: start-up, pyarrow measured ~180 ms, needed only to write or read a table
    import pyarrow as pa  # noqa: PLC0415
    import pyarrow.parquet as pq  # noqa: PLC0415

    sink = pa.BufferOutputStream()
    table = pa.Table.from_arrays([to_arrow(np.asarray(v)) for v in series.values()], names=list(series))
    pq.write_table(table, sink, use_dictionary=False)
    return sink.getvalue().to_pybytes()


def pack(results: list[RunRecord]) -> list[RunRecord]:
    """Worker side: replace each result's ``series`` by its Parquet bytes (smaller to send,
    and the encoding runs in parallel instead of in the main process), and keep beside them
    the few columns the leaderboard reads (:func:`summary_columns`)."""
    return [
        replace(r, series=None, parquet=parquet_bytes(r.series), leaderboard_columns=summary_columns(r.series))
        if r.series is not None
        else r
        for r in results
    ]


def summary_columns(series: dict) -> dict:
    """The columns of a per-step table that the leaderboard reads (:data:`SUMMARY_COLUMNS`), those
    whose Parquet round trip is exact (:func:`to_arrow`: native integers and floats)."""
    out = {}
    for name in SUMMARY_COLUMNS:
        v = np.asarray(series.get(name, ()))
        if name in series and v.ndim == 1 and v.dtype.kind in "iuf" and v.dtype.isnative:
            out[name] = v
    return out


def footer(source):
    """(rows, column names) of a Parquet file or buffer; raises OSError/ValueError when unreadable."""
    # lazy: start-up, pyarrow measured ~180 ms, needed only to write or read a table
    import pyarrow as pa  # noqa: PLC0415
    import pyarrow.parquet as pq  # noqa: PLC0415

    src = pa.BufferReader(source) if isinstance(source, bytes) else source
    try:
        meta = pq.ParquetFile(src).metadata
    except (pa.ArrowException, OSError, ValueError) as err:
        raise ValueError(str(err).splitlines()[0] if str(err) else type(err).__name__) from None
    return meta.num_rows, list(meta.schema.to_arrow_schema().names)


def describe(data: bytes) -> dict:
    """What a unit's record says of its table: rows, columns, size and SHA-256 of the bytes."""
    rows, names = footer(data)
    return {"rows": rows, "columns": names, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}
