"""Independent evaluations in worker processes, the costliest first (every paper reproduction uses it).

:class:`Job` is one planned evaluation (a ``replay eval`` configuration: dataset and its parameters,
filters and theirs, task parameters, runs, seed offset); :func:`evaluate_jobs` computes a list of them
with :func:`run_longest_first` and returns them in the plan's order.

A reproduction lists independent evaluations (``replay eval`` configurations);
:func:`run_longest_first` computes them in ``REPLAY_WORKERS`` processes (default
2, :func:`workers`), the most expensive first so that the last ones to finish are
short (the workers end together), and yields ``(index, result)`` as each one
finishes, the progress on stderr (tqdm: a bar on a terminal, a line per job otherwise). One worker runs them in this
process, in the same order. Every evaluation draws from its own seeded streams
(``replay.util.seeds``: (seed, run, stream)), so where and in which order it runs
changes no number: the results equal those of the serial run.

Workers are forked where the platform allows (they start with everything
imported) and end with the process that started them
(:func:`replay.campaign.workers.init_worker`); each gets cores // workers BLAS and
compiled-kernel threads (``REPLAY_THREADS``), so two workers on two cores do
not run four threads.
"""

from __future__ import annotations

import os
from concurrent.futures import as_completed
from contextlib import contextmanager
from dataclasses import dataclass, field

from replay.campaign.workers import process_pool
from replay.run.eval_options import EvalOptions
from replay.run.evaluation import evaluate
from replay.util.errors import ReplayError
from replay.util.progress import Progress


def workers() -> int:
    """Worker processes of a reproduction: ``REPLAY_WORKERS`` (default 2), at least 1."""
    raw = os.environ.get("REPLAY_WORKERS", "2")
    try:
        n = int(raw)
    except ValueError:
        raise ReplayError(f"REPLAY_WORKERS must be a whole number of worker processes (got {raw!r})") from None
    return max(1, n)


def longest_first(costs) -> list[int]:
    """Indices of ``costs`` from the largest down (ties: list order)."""
    return sorted(range(len(costs)), key=lambda i: -costs[i])


@contextmanager
def pool(n: int):
    """A process pool of ``n`` workers (None for one: the caller's process computes)."""
    if n <= 1:
        yield None
        return
    ex = process_pool(n)
    try:
        yield ex
    finally:
        ex.shutdown(wait=True, cancel_futures=True)


def run_longest_first(fn, args: list, costs: list, labels: list, executor=None, quiet: bool = False, prefix: str = ""):
    """``fn(args[i])`` for every i, the largest ``costs`` first, in ``executor`` (a pool of
    :func:`pool`; None: here, one after another). Yields ``(i, result)`` as each finishes; the progress
    (:class:`replay.util.progress.Progress` labelled ``<prefix>reproduce``, weighted by ``costs``) names the
    last job done, a line per job off a terminal, nothing when ``quiet``."""
    order = longest_first(costs)
    weight = sum(costs) if all(c > 0 for c in costs) else None  # a cost of 0: count jobs instead
    bar = Progress(len(order), quiet, every=0.0, label=f"{prefix}reproduce", unit="job", total_weight=weight)

    def note(i):
        bar.set_postfix_str(f"{labels[i]} done", refresh=False)
        bar.update(1, weight=costs[i] if weight else None)

    try:
        if executor is None:
            for i in order:
                out = fn(args[i])
                note(i)
                yield i, out
            return
        futures = {executor.submit(fn, args[i]): i for i in order}
        try:
            for fut in as_completed(futures):
                i = futures[fut]
                out = fut.result()
                note(i)
                yield i, out
        finally:
            for fut in futures:
                fut.cancel()
    finally:
        bar.close()


@dataclass
class Job:
    """One evaluation: ``filters`` with ``filter_params`` on ``dataset`` with ``dataset_params``."""

    key: str
    dataset: str
    filters: tuple
    dataset_params: dict = field(default_factory=dict)
    filter_params: dict = field(default_factory=dict)
    task_params: dict = field(default_factory=dict)
    runs: int = 0  # 0: the reproduction's default
    seed: int = 0  # added to the reproduction's seed


def _evaluate(args):
    """One job's evaluation (what a worker process runs), through ``reduce`` when given."""
    job, runs, seed, data_dir, reduce = args
    params = dict(dataset_params=job.dataset_params or None, filter_params=job.filter_params)
    params |= dict(task_params=job.task_params or None, runs=job.runs or runs, seed=seed + job.seed)
    ev = evaluate(job.dataset, EvalOptions(filters=job.filters, data_dir=data_dir, **params))
    return ev if reduce is None else reduce(job, ev)


def evaluate_jobs(jobs: list[Job], runs: int, seed: int, data_dir=None, quiet=False, prefix="", reduce=None) -> dict:
    """``{key: Evaluation}`` of ``jobs`` in the plan's order, computed in worker processes the costliest first
    (runs × particles, 30 for a filter without; the progress on stderr unless ``quiet``). ``reduce(job,
    evaluation)``, a module-level function, runs in the worker and its result comes back instead of the
    evaluation (a run's records can weigh a megabyte)."""
    keys = [j.key for j in jobs]
    if len(set(keys)) != len(keys):
        raise ValueError(f"jobs planned twice: {sorted({k for k in keys if keys.count(k) > 1})}")
    runs_of = [j.runs or runs for j in jobs]
    particles = [sum(j.filter_params.get(f, {}).get("n_particles", 30) for f in j.filters) for j in jobs]
    cost, labels = [n * p for n, p in zip(runs_of, particles)], [f"{j.key} ({n} runs)" for j, n in zip(jobs, runs_of)]
    with pool(workers()) as ex:
        args = [(j, runs, seed, data_dir, reduce) for j in jobs]
        done = dict(run_longest_first(_evaluate, args, cost, labels, ex, quiet, prefix))
    return {j.key: done[i] for i, j in enumerate(jobs)}
