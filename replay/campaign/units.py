"""Units and jobs: what one worker computes.

A **unit** is one run of one configuration (:class:`replay.run.pipeline.Config`).
Its key is ``<config_hash>/<run>`` (:func:`replay.run.pipeline.config_hash`: the
configuration with every parameter default filled in, so ``{}`` and the
defaults name the same configuration). Adding a filter or a run never changes
an existing key.

A **job** is a block of runs of one configuration, ``runs [b*batch, (b+1)*batch)``
less those already stored; :func:`execute_job` is :func:`replay.run.pipeline.run_block`
— the pipeline ``replay eval`` runs too — and never raises: a run that fails
comes back with ``status = "failed"`` and its error.

A recorded estimate's configuration (``recorded:<name>``, :mod:`replay.campaign.spec`)
has one unit, run 0: :func:`replay.run.pipeline.run_block` computes only that run of a
job (:func:`replay.run.pipeline.runs_of`) and returns no record for the others.
"""

from __future__ import annotations

from dataclasses import dataclass

from replay.run.pipeline import run_block
from replay.scoring.record import RunRecord


@dataclass
class Job:
    config: dict
    config_hash: str
    runs: list
    data_dir: str | None = None


def execute_job(job: Job) -> list[RunRecord]:
    """Every run of ``job``: one record per run (never raises)."""
    return run_block(job.config, job.runs, job.data_dir)
