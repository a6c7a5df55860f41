"""The record of one run: what :func:`replay.run.pipeline.run_block` returns for each run, what a
campaign stores as ``units/<config_hash>/<run>.json`` and what every leaderboard reads.

One :class:`RunRecord` per run. A run is ``done`` (its ``metrics`` and per-step ``series``) or
``failed`` (its ``error``, one line, and ``traceback``). The fields after ``series`` are present
only where they apply (None otherwise) and are not written when absent.

Where a record crosses a file (a campaign's unit record, :mod:`replay.campaign.store`), it goes
through :meth:`RunRecord.to_dict` and :meth:`RunRecord.from_dict`: the JSON object keeps the keys
and their order of the records written before this class existed (``run, status, metrics`` or
``run, status, error, traceback``, the optional keys, then what the store adds: ``key, config_hash,
version, table, record_sha256``), so stored units and their checksums read and write alike. Keys a
reader does not know (a record of another version) are kept in ``extra`` and written back after
the others. The in-memory fields (``series``, ``problem``, ``estimates``, ``errors``, ``parquet``,
``leaderboard_columns``) never go into that object: the per-step table is stored beside it as
Parquet. Between a campaign's processes (a local pool, Dask) the record itself travels (pickled).

Lives in :mod:`replay.scoring` (below ``run``, ``campaign``, ``tune`` and ``outputs``) so that every
layer that reads a record can name its type.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

DONE, FAILED = "done", "failed"
IN_MEMORY = ("series", "problem", "estimates", "errors", "parquet", "leaderboard_columns", "extra")


@dataclass
class RunRecord:
    """One run of one configuration (module docstring)."""

    run: int  # the run index (its seed streams: replay.util.seeds)
    status: str  # DONE or FAILED
    metrics: dict | None = None  # done: replay.scoring.metrics.run_metrics, likelihood, seconds (filter time)
    series: dict | None = None  # done, in memory: the per-step table (k, t, x<i>, P<ii>, ref_/err_<axis>, nees, ...)
    error: str | None = None  # failed: one line (replay.run.failures.describe)
    traceback: str | None = None  # failed: the last 4000 characters of the traceback
    content_checked: bool | None = None  # a registered recording: whether anything published confirms the file
    reference_input: str | None = None  # the reference is one of the filter's inputs (replay.scoring.marks)
    reference: str | None = None  # where the reference comes from (replay.scoring.provenance: its kind)
    reference_shares: str | None = None  # the fed inputs that share a source with the reference
    unconstrained: str | None = None  # attitude angles no input measures, joined by " | "
    rejected: dict | None = None  # per-sensor outlier gating: measurements rejected (replay.filters.gating)
    problem: object = None  # in memory (keep=True): the run's Problem (replay.tasks)
    estimates: object = None  # in memory (keep=True): the filter's Estimates
    errors: dict | None = None  # in memory (keep=True): the error series (replay.scoring.scorer.errors)
    note: str | None = None  # a recorded estimate: what was associated (replay.trajectory.recorded)
    key: str | None = None  # stored: "<config_hash>/<run>"
    config_hash: str | None = None  # stored: the configuration's hash (replay.util.canonical.config_hash)
    version: str | None = None  # stored: the replay version that computed it
    table: dict | None = None  # stored: the Parquet table's rows, columns, bytes and sha256
    record_sha256: str | None = None  # stored: the record's own checksum (replay.campaign.records)
    parquet: bytes | None = None  # between processes: the per-step table as Parquet bytes (campaign workers)
    leaderboard_columns: dict | None = None  # between processes: the table's columns the leaderboard reads
    extra: dict = field(default_factory=dict)  # read from a file: keys this version does not know, kept

    @property
    def done(self) -> bool:
        return self.status == DONE

    @property
    def diverged(self) -> bool:
        """A done run whose filter diverged (``metrics["diverged"]``)."""
        return self.done and bool(self.metrics["diverged"])

    @property
    def table_sha256(self) -> str | None:
        """The SHA-256 of the stored per-step table its record describes (None when not described)."""
        return self.table.get("sha256") if isinstance(self.table, dict) else None

    def metric(self, name: str, default=float("nan")):
        """A per-run metric (``default`` when the run has none)."""
        return (self.metrics or {}).get(name, default)

    def to_dict(self) -> dict:
        """The JSON object of the record (module docstring): present fields but the in-memory ones,
        in the order above, then ``extra``."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in IN_MEMORY}
        return {k: v for k, v in out.items() if v is not None} | self.extra

    @classmethod
    def from_dict(cls, d: dict) -> RunRecord:
        """The record of a JSON object written by :meth:`to_dict` (or by replay before this class)."""
        known = {f.name for f in fields(cls)} - set(IN_MEMORY)
        return cls(**{k: v for k, v in d.items() if k in known}, extra={k: v for k, v in d.items() if k not in known})
