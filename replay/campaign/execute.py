"""Running a campaign: plan the missing units, execute jobs, store results as they finish.

One code path for every backend: :func:`plan` lists the jobs (blocks of runs
not yet stored), a backend maps :func:`replay.campaign.units.execute_job` over
them and yields (job, results) as jobs finish, and the main process stores
each unit (:class:`~replay.campaign.store.Store`) and advances the progress.
Workers only compute (and encode each unit's per-step table as Parquet bytes,
:func:`execute_packed`, so that the encoding runs in parallel); only the main
process writes files, so a Dask worker on another machine needs no access to the
output directory.

Backends:

* ``serial`` — in this process (chosen for one job, or ``--workers 1``);
* ``processes`` — a local process pool, ``--workers N`` (default: all cores);
* ``dask`` — a Dask distributed cluster, ``--scheduler tcp://host:port``, or a
  LocalCluster of N single-threaded worker processes on 127.0.0.1
  (``--dask-local N``). A scheduler that does not answer within
  ``connect_timeout`` seconds raises a one-line ReplayError. A remote worker imports
  replay and reads the dataset files itself: it needs the same replay installed and
  the data at the same paths as this machine (the jobs carry the data directory).

The numbers do not depend on the backend, the number of workers or the order
in which jobs finish: every run draws from its own seed streams and jobs are
fixed blocks of runs.
"""

from __future__ import annotations

import gc
import logging
import os
from concurrent.futures import as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from replay.run.pipeline import config_hash, runs_of
from replay.scoring.record import FAILED, RunRecord
from replay.util.errors import ReplayError
from replay.util.staging import check_space
from replay.util.progress import Progress, particle_weight

from . import board, index
from .lock import locked
from .noise_check import check_noise
from .spec import Campaign
from replay.util.files import sync_dir, write_bytes, write_json

from .store import Store, pack
from .units import Job, execute_job
from .workers import connect_scheduler, like_a_worker, process_pool, start_method


PLAN_PROGRESS = 1000  # configurations from which checking the stored units shows its progress
UNIT_BYTES = 8192  # the least a stored unit takes on disk: a record and a table, a 4 KiB block each


def plan(campaign: Campaign, store: Store, retry_failed: bool = False, data_dir=None) -> list[Job]:
    """Jobs for every unit not yet stored intact, in blocks of ``campaign.batch`` runs."""
    return _plan(campaign, store, retry_failed, data_dir)[0]


def _plan(campaign: Campaign, store: Store, retry_failed: bool = False, data_dir=None, progress=None):
    """(jobs, damaged, stored): the jobs; ``(config_hash, run, problem)`` of each damaged unit
    found (``problem`` one line naming the file), which the jobs compute again, of a damaged
    ``config.json`` or index (run None; rewritten here) and of a configuration the index lists
    whose directory is gone (run -1; computed again); the number of units stored intact.

    Up front, only the index (:mod:`.index`: one file, one flush) and the missing ``units/``
    directories (no flush each) are written; each ``config.json`` comes with its first units.
    ``progress``: a :class:`Progress` over the configurations checked."""
    jobs, damaged, stored = [], [], 0
    cfgs = [cfg.as_dict() for cfg in campaign.configs]
    hashes = [config_hash(c) for c in cfgs]
    listed, dirs, damaged_index = index.read(store.out)
    if damaged_index is not None:
        damaged.append((None, None, damaged_index))
    made = False
    for c, h in zip(cfgs, hashes):
        d = store.units / h
        if not d.is_dir():
            if h in listed:
                damaged.append((h, -1, f"{d}: missing (listed in {store.out / index.NAME})"))
            d.mkdir(parents=True, exist_ok=True)
            made = True
        good, bad = store.scan(h)
        if (good or bad) or (d / "config.json").exists():  # stored units come with their config.json
            _, problem = store.read_config(h)
            if problem is not None:
                store.save_config(h, c)
                damaged.append((h, None, problem))
        stored += len(good)
        have = {r for r, rec in good.items() if not retry_failed or rec.done}
        damaged.extend((h, r, bad[r]) for r in sorted(bad))
        wanted = set(runs_of(c, range(campaign.runs)))  # a recorded estimate: run 0 only
        for start in range(0, campaign.runs, campaign.batch):
            runs = [
                r for r in range(start, min(start + campaign.batch, campaign.runs)) if r in wanted and r not in have
            ]
            if runs:
                jobs.append(Job(c, h, runs, data_dir or campaign.data_dir))
        if progress is not None:
            progress.update(1)
    if made:
        sync_dir(store.units)
    where = data_dir or campaign.data_dir
    new_dirs = {c["dataset"]: str(Path(where).resolve()) for c in cfgs} if where else {}
    new, names = {**listed, **dict(zip(hashes, cfgs))}, index.names(store.out)
    if new != listed or {**dirs, **new_dirs} != dirs or {**names, **campaign.names} != names or damaged_index:
        write_json(store.out / index.NAME, index.document(new, {**dirs, **new_dirs}, {**names, **campaign.names}))
    return jobs, damaged, stored


def execute_packed(job: Job) -> list[RunRecord]:
    """What a worker runs: the job's results with each per-step table already Parquet-encoded."""
    return pack(execute_job(job))


def _serial(jobs):
    for job in jobs:
        yield job, execute_packed(job)


@contextmanager
def _processes(workers: int, warm: list | None = None):
    """A local pool of ``workers`` processes as a job mapper. ``warm``: jobs run here, before the pool
    is forked, with the workers' thread count, their results dropped: the workers start with the
    kernels those jobs compiled (``replay tune`` passes one short run of each filter: a trial's jobs
    are one filter's runs spread over the workers, which on a cold cache each compiled the same
    kernels. A cold ``replay tune sim/auv-sonar -f ekf,stcpf --runs 2 --dataset-param steps=60
    --trials 3`` on 2 workers took 43 CPU s and 25.8 s; 20 CPU s and 21 s with this; on a warm cache
    the short runs cost milliseconds). Not for campaigns: their jobs are mostly distinct filters,
    which the workers compile in parallel."""
    method = start_method()
    if method == "fork":  # imported once here rather than in every worker
        # lazy: only a forked pool's parent needs it
        import pyarrow.parquet  # noqa: F401, PLC0415
    frozen = method == "fork" and not gc.get_freeze_count()
    pool = None

    def run(jobs):
        nonlocal pool
        if pool is None:
            if warm and method == "fork":  # a spawned worker would compile on its own anyway
                with like_a_worker(workers):  # the workers' threads: it compiles what they run
                    for job in warm:
                        execute_packed(job)
            if frozen:  # what exists now is never collected in a worker: no scan (nor page copy) of it there
                gc.freeze()
            pool = process_pool(workers)
        futures = {pool.submit(execute_packed, job): job for job in jobs}
        for fut in as_completed(futures):
            yield futures[fut], _result(fut, futures[fut])

    try:
        yield run
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        if frozen:
            gc.unfreeze()


@contextmanager
def _dask(scheduler: str | None, n_local: int | None, connect_timeout: float):
    try:
        # lazy: an optional extra, heavy to import
        from distributed import Client, LocalCluster, as_completed  # noqa: PLC0415
    except ImportError:
        raise ReplayError(
            "Dask is not installed: from a checkout of replay, pip install -e \".[campaign]\" "
            "(it adds dask[distributed])"
        ) from None
    logging.getLogger("distributed").setLevel(logging.ERROR)
    cluster = None
    try:
        if scheduler:
            client = connect_scheduler(scheduler, connect_timeout)  # bounds the handshake too
        else:
            cluster = LocalCluster(
                n_workers=n_local, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
            )
            client = Client(cluster, set_as_default=False)
    except (OSError, TimeoutError) as err:
        if cluster is not None:
            cluster.close()
        raise ReplayError(
            f"Dask scheduler {scheduler or 'LocalCluster'}: no answer within "
            f"{connect_timeout:g} s ({type(err).__name__})"
        ) from None

    def run(jobs):
        futures = client.map(execute_packed, jobs, pure=False)
        owner = {f.key: j for f, j in zip(futures, jobs)}
        with client.as_current():
            for fut in as_completed(futures):
                yield owner[fut.key], _result(fut, owner[fut.key])

    try:
        yield run
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _result(fut, job):
    """A job's results; a job that died as a whole (worker lost) marks each of its runs failed."""
    try:
        return fut.result()
    except Exception as err:  # noqa: BLE001 — recorded per unit, the campaign goes on
        return [RunRecord(r, FAILED, error=f"{type(err).__name__}: {err}".splitlines()[0]) for r in job.runs]


@dataclass(frozen=True)
class RunOptions:
    """How a campaign is computed, never what it computes (the numbers do not depend on these): the
    backend (``workers``, ``scheduler``, ``dask_local``, ``connect_timeout``: module docstring), the
    progress (``quiet``, ``progress_stream``), ``retry_failed`` (compute failed units again), ``data_dir``
    (where the datasets are found), ``limit`` (stop after that many jobs: tests of resuming) and ``wait``
    (block until a running campaign on the directory has finished instead of refusing)."""

    workers: int | None = None
    scheduler: str | None = None
    dask_local: int | None = None
    quiet: bool = False
    retry_failed: bool = False
    data_dir: os.PathLike | str | None = None
    limit: int | None = None
    connect_timeout: float = 5.0
    progress_stream: object = None
    wait: bool = False


def run(campaign: Campaign, out, options: RunOptions | None = None) -> dict:
    """Compute every unit of ``campaign`` not yet stored intact in ``out``; write the leaderboard.

    Holds the directory's campaign lock throughout (:mod:`.lock`). ``options``: a :class:`RunOptions`
    (None: the defaults). Returns counts; ``damaged`` lists the damaged units
    found and computed again, ``rewritten`` the damaged ``config.json`` files replaced (one
    line each, naming the file).
    """
    out, o = Path(out), options or RunOptions()
    try:
        out.mkdir(parents=True, exist_ok=True)
        with locked(out, wait=o.wait):
            return _run_locked(campaign, out, o)
    except OSError as err:  # a full or read-only disk, a name too long: the stored units are intact
        for name in ("leaderboard.csv", "paired.csv"):
            try:
                (out / f".{name}.{os.getpid()}.tmp").unlink(missing_ok=True)
            except OSError:
                pass
        where = err.filename or out
        raise ReplayError(
            f"{where}: cannot write ({err.strerror or type(err).__name__}); the units stored "
            f"in {out} before are intact: free space and run the campaign again"
        ) from None


def _run_locked(campaign, out, o: RunOptions) -> dict:
    store = Store(out)
    hashes = [config_hash(c.as_dict()) for c in campaign.configs]
    stored_before = 0
    listed, _, bad_index = index.read(out)
    for h, _ in store.configs(skip=hashes, listed=listed if bad_index is None else {}):  # other campaign
        # files' configurations: not recomputed here (a unit directory that is a file: refused)
        good, bad = store.scan(h)
        if bad:
            raise ReplayError(
                f"{bad[min(bad)]}; this configuration is not in {campaign.path}: run the "
                f"campaign file that made it on {out} to recompute it"
            )
        stored_before += len(good)
    if campaign.path.resolve() != (out / "campaign.toml").resolve():
        write_bytes(out / "campaign.toml", campaign.path.read_bytes())
    checking = None
    if len(campaign.configs) >= PLAN_PROGRESS:  # what it does before the first unit, and how far
        checking = Progress(
            len(campaign.configs),
            o.quiet,
            o.progress_stream,
            label="campaign: checking stored units",
            unit="configuration",
        )
    try:
        jobs, damaged, stored = _plan(campaign, store, o.retry_failed, o.data_dir, checking)
    finally:
        if checking is not None:
            checking.close()
    stored_before += stored
    if o.limit is not None:
        jobs = jobs[: o.limit]
    scheduled = {(j.config_hash, r) for j in jobs for r in j.runs}
    total = sum(len(j.runs) for j in jobs)
    counts = {
        "jobs": len(jobs),
        "units": total,
        "done": 0,
        "failed": 0,
        "damaged": [what for h, r, what in damaged if r is not None and (h, r) in scheduled],
        "missing": [what for h, r, what in damaged if r == -1],
        "rewritten": [what for h, r, what in damaged if r is None],
        "stored_before": stored_before,
        "backend": "none",
    }
    if jobs:
        check_noise(jobs, campaign.path)  # per-filter Q, R, P0 of the task model's size: before any unit
        check_space(out, "--out", need=total * UNIT_BYTES)  # before any work: at least this much
        backend, counts["backend"] = open_backend(o.workers, o.scheduler, o.dask_local, o.connect_timeout, len(jobs))
        weights = {
            (j.config_hash, tuple(j.runs)): particle_weight(j.config["filter_params"], len(j.runs)) for j in jobs
        }
        if counts["backend"] != "serial":  # the longest first: the short ones then even out the workers' ends
            jobs = sorted(jobs, key=lambda j: -weights[(j.config_hash, tuple(j.runs))])
        progress = Progress(total, o.quiet, o.progress_stream, label="campaign", total_weight=sum(weights.values()))
        saved = set()
        try:
            with backend as mapper:
                for job, results in mapper(jobs):
                    store_job(store, job, results, saved)
                    bad = sum(not r.done for r in results)
                    counts["done"] += len(results) - bad
                    counts["failed"] += bad
                    progress.update(
                        len(results), bad, weight=weights.get((job.config_hash, tuple(job.runs)), len(results))
                    )
        finally:
            progress.close()
    counts["rows"] = board.summarise(out, hashes, store)
    return counts


def open_backend(workers, scheduler, dask_local, connect_timeout: float, n_jobs: int, warm: list | None = None):
    """(a context manager giving the job mapper, its name): Dask, a local pool, or this process.
    ``warm`` (a local pool): see :func:`_processes`."""
    workers = workers or os.cpu_count() or 1
    if scheduler or dask_local:
        return _dask(scheduler, dask_local, connect_timeout), "dask"
    if workers == 1 or n_jobs == 1:
        return _nullcontext(_serial), "serial"
    return _processes(min(workers, n_jobs), warm), f"processes({min(workers, n_jobs)})"


def spread_block(runs: int, batch: int, workers, scheduler) -> int:
    """Runs per job of one trial: at most ``batch``, and few enough that a trial's runs spread over
    the workers (trials run one after another; 5 runs in one block of 25 kept one of two cores idle).
    ``workers``: the local pool's or local Dask cluster's size (default: the cores); a remote
    ``scheduler``'s size is not known here: taken as 4. Numbers do not depend on the block: a run's
    depend only on (seed, run)."""
    w = workers or (4 if scheduler else os.cpu_count() or 1)
    return max(1, min(batch, -(-runs // w)))


def store_job(store: Store, job: Job, results, saved: set) -> None:
    """A finished job's units into ``store`` (its ``config.json`` with the configuration's first units)."""
    if job.config_hash not in saved:
        saved.add(job.config_hash)
        store.save_config(job.config_hash, job.config)
    store.write_job(job.config_hash, results)


@contextmanager
def _nullcontext(value):
    yield value
