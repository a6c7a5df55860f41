"""``replay tune``: trials as campaign units, the held-out scoring, the leaderboard and ``tuned.toml``.

Layout of ``DIR``: a campaign result directory (``configs.json``, ``units/<hash>/...``:
every trial's configuration on the training data, and the default and tuned
configurations on the test data; :mod:`replay.campaign.store`), ``study.db`` (the
Optuna studies, :mod:`.study`), ``tune.json`` (what was asked), ``leaderboard.csv``
(one row per filter with its default parameters and one with its tuned ones),
``tuned.toml`` (the tuned configurations on the test data, a campaign file).
"""

from __future__ import annotations

import json
import math
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from replay.campaign import execute
from replay.campaign.lock import locked
from replay.campaign.spec import Campaign
from replay.campaign.store import Store
from replay.util.files import write_csv, write_json
from replay.run.eval_options import DEFAULTS
from replay.run.evaluation import observes_position
from replay.run.pipeline import Config, build_problem, config_hash, plain
from replay.filters import make_filter
from replay.scoring import summary
from replay.scoring.record import RunRecord
from replay.tasks import make_task
from replay.util.progress import Progress, particle_weight

from . import objectives, study as studies
from .space import _declared
from .splits import Split
from replay.tune.write import write_tuned

COLUMNS = [
    "dataset",
    "task",
    "filter",
    "label",
    "params",
    "tuned_on",
    "tested_on",
    "objective",
    "trials",
    "train_score",
    "test_score",
    "overlap",
    "runs",
    "seed",
    "pos_rmse",
    "pos_rmse_median",
    "lost",
    "diverged",
    "anees",
    "train_config_hashes",
    "test_config_hashes",
]


@dataclass
class Tune:
    """What ``replay tune`` was asked (built and checked by :func:`replay.tune.check.prepare`)."""

    task: str
    filters: list
    dims: dict  # filter -> [space.Dim]
    trials: int
    objective: str
    weights: dict
    split: Split
    runs: int
    seed: int
    task_params: dict = field(default_factory=dict)
    first: int | None = None
    alignment: str = DEFAULTS["alignment"]
    data_dir: str | None = None
    batch: int = DEFAULTS["batch"]

    def config(self, dataset, dparams, seed, name, fparams, tparams) -> Config:
        task = plain(make_task(self.task, **{**self.task_params, **tparams}).params())
        return Config(
            dataset,
            plain(dparams),
            self.first,
            self.task,
            task,
            name,
            plain(make_filter(name, **fparams).params()),
            seed,
            self.alignment,
            None,
        )

    def configs(self, part: str, name: str, params: dict) -> list[Config]:
        """The configurations of filter ``name`` with the searched ``params`` ({key: value}) on
        the training (``part`` = train) or test data."""
        fp = {k.split(".", 1)[1]: v for k, v in params.items() if k.split(".", 1)[0] == name}
        tp = {k.split(".", 1)[1]: v for k, v in params.items() if k.startswith("task.")}
        seed = self.split.train_seed if part == "train" else self.split.test_seed
        return [
            self.config(d, p, seed if seed is not None else self.seed, name, fp, tp)
            for d, p in (self.split.train if part == "train" else self.split.test)
        ]

    def defaults(self, name: str) -> dict | None:
        """{key: default} of filter ``name``'s searched parameters, or None when a default lies outside
        the space (the first trial of a study is the defaults, so tuning never ends worse on training)."""
        have = {
            **{f"{name}.{p.name}": p.default for p in _declared(name)},  # params() leaves out default noise
            **{f"task.{k}": v for k, v in make_task(self.task, **self.task_params).params().items()},
        }
        out = {d.key: have.get(d.key) for d in self.dims[name]}
        inside = all(
            v in d.choices
            if d.kind == "choice"
            else isinstance(v, (int, float)) and not isinstance(v, bool) and d.low <= v <= d.high
            for d, v in zip(self.dims[name], out.values())
        )
        return out if inside else None

    def fingerprint(self, name: str) -> dict:
        return plain(
            {
                "train": self.split.train,
                "train_seed": self.split.train_seed,
                "task": self.task,
                "task_params": self.task_params,
                "objective": self.objective,
                "space": {d.key: d.text() for d in self.dims[name]},
                "runs": self.runs,
                "seed": self.seed,
                "first": self.first,
                "alignment": self.alignment,
            }
        )


class Runner:
    """Computes configurations as campaign units in ``out`` on one backend, kept open."""

    def __init__(self, t: Tune, out: Path, backend, block: int | None = None):
        self.t, self.out, self.store, self.mapper, self.saved = t, out, Store(out), backend, set()
        self.block = block or t.batch  # runs per job (a trial's runs spread over the workers)

    def records(self, cfgs: list[Config]) -> list[list[RunRecord]]:
        camp = Campaign(None, "tune", self.t.runs, 0, self.block, self.t.data_dir, list(cfgs))
        jobs = execute.plan(camp, self.store, data_dir=self.t.data_dir)
        for job, results in self.mapper(jobs):
            execute.store_job(self.store, job, results, self.saved)
        return [self.store.records(config_hash(c.as_dict())) for c in cfgs]

    def why_inf(self, cfgs: list[Config]) -> str:
        """Why the objective over ``cfgs`` is infinite (:func:`objectives.why_inf`, the first such dataset)."""
        return next((w for w in (objectives.why_inf(self.t.weights, r) for r in self.records(cfgs)) if w), "")

    def score(self, cfgs: list[Config]) -> float:
        """The objective over ``cfgs`` (the mean of each dataset's)."""
        vals = [objectives.value(self.t.weights, recs) for recs in self.records(cfgs)]
        return float(sum(vals) / len(vals))


def tune(
    t: Tune,
    out,
    *,
    workers=None,
    scheduler=None,
    dask_local=None,
    quiet=False,
    progress_stream=None,
    connect_timeout: float = 5.0,
    wait: bool = False,
    store_dir=None,
) -> dict:
    """Run (or resume) every filter's study, score default and tuned configurations on the test
    data, write ``leaderboard.csv`` and ``tuned.toml``; returns {"rows", "budget", "paths"}.
    ``store_dir``: where the units are stored (default ``out``; a campaign's tunes share one)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    units = Path(store_dir) if store_dir is not None else out
    with ExitStack() as held:
        held.enter_context(locked(out, wait=wait, who="replay tune"))
        if units != out:
            held.enter_context(locked(units, wait=wait, who="replay tune or campaign"))
        store = studies.storage(out, units)
        opened = {f: studies.open_study(store, f, t.fingerprint(f), out / "study.db", units) for f in t.filters}
        write_json(out / "tune.json", _asked(t))  # once every study is known to be this configuration's
        todo = {f: max(0, t.trials - len(studies.complete(s))) for f, s in opened.items()}
        block = execute.spread_block(t.runs, t.batch, workers or dask_local, scheduler)
        n_jobs = -(-t.runs // block) * max(len(t.split.train), len(t.split.test))
        ctx, _ = execute.open_backend(workers, scheduler, dask_local, connect_timeout, n_jobs, _warm_jobs(t))
        failed: dict = {}  # filter -> why each of its trials of this invocation scored inf
        cost = {f: {p: _cost(t.configs(p, f, {}), t.runs) for p in ("train", "test")} for f in t.filters}
        progress = Progress(
            sum(todo.values()) + 2 * len(t.filters),
            quiet,
            progress_stream,
            label="tune",
            unit="step",
            total_weight=sum(todo[f] * cost[f]["train"] + 2 * cost[f]["test"] for f in t.filters),
        )  # the trials, then each filter's default and tuned held-out scoring, weighted by their cost
        try:
            with ctx as mapper, np.errstate(all="ignore"):  # diverged runs' NaNs: counted, not warned
                run = Runner(t, units, mapper, block)
                for name, st in opened.items():
                    for _ in range(todo[name]):
                        trial, params = studies.next_trial(st, t.dims[name], t.seed, name, t.defaults(name))
                        cfgs = t.configs("train", name, params)
                        value = run.score(cfgs)
                        st.tell(trial, value)
                        progress.update(1, 0 if math.isfinite(value) else 1, weight=cost[name]["train"])
                        if not math.isfinite(value):  # said after the board: why the trial scored inf
                            failed.setdefault(name, []).append(run.why_inf(cfgs))
                rows = _board(t, run, opened, lambda name: progress.update(1, weight=cost[name]["test"]))
        finally:
            progress.close()
        marked = [
            k
            for k in ("still", "reference_input", "reference", "reference_shares", "unconstrained")
            if any(r.get(k) for r in rows)
        ]
        write_csv(rows, out / "leaderboard.csv", COLUMNS + marked)
        paths = {"leaderboard": out / "leaderboard.csv", "study": out / "study.db"}
        paths.update(write_tuned(t, out, rows))
    return {
        "rows": rows,
        "budget": {f: min(t.trials, len(studies.complete(s))) for f, s in opened.items()},
        "paths": paths,
        "failed": failed,
    }


WARM_SAMPLES = 50  # samples of the short run that compiles a filter's kernels before the pool forks


def _warm_jobs(t: Tune) -> list:
    """One short run (the first :data:`WARM_SAMPLES` samples, run 0) of each filter with its defaults
    on the first training dataset: run before the workers are forked, so that they start with its
    kernels compiled (:func:`replay.campaign.execute._processes`); their results are not kept."""
    jobs = []
    for name in t.filters:
        c = t.configs("train", name, {})[0].as_dict()
        c["first"] = WARM_SAMPLES if c["first"] is None else min(c["first"], WARM_SAMPLES)
        jobs.append(execute.Job(c, "warm", [0], t.data_dir))
    return jobs


def _asked(t: Tune) -> dict:
    return plain(
        {
            "task": t.task,
            "filters": t.filters,
            "trials": t.trials,
            "objective": t.objective,
            "space": {f: {d.key: d.text() for d in ds} for f, ds in t.dims.items()},
            "train": t.split.train,
            "test": t.split.test,
            "train_seed": t.split.train_seed,
            "test_seed": t.split.test_seed,
            "tuned_on": t.split.tuned_on,
            "tested_on": t.split.tested_on,
            "overlap": t.split.overlap,
            "runs": t.runs,
            "seed": t.seed,
            "task_params": t.task_params,
            "first": t.first,
            "alignment": t.alignment,
        }
    )


def _cost(cfgs: list[Config], runs: int) -> float:
    """The expected cost of ``runs`` runs of each configuration (:func:`particle_weight`), each in
    proportion to its share of the log (a view ``segment = "A:B"``: B - A)."""

    def share(c):
        a, _, b = str(c.dataset_params.get("segment", "0:1")).partition(":")
        try:
            return max(0.05, float(b or 1) - float(a or 0))
        except ValueError:
            return 1.0

    return sum(particle_weight(c.filter_params, runs) * share(c) for c in cfgs)


def _board(t: Tune, run: Runner, opened: dict, done) -> list[dict]:
    rows = []
    for name, st in opened.items():
        best = studies.best(st, t.trials)
        kinds = [("default", {})] + ([("tuned", dict(best.params))] if best is not None else [])
        for kind, params in kinds:
            train, test = t.configs("train", name, params), t.configs("test", name, params)
            train_score = run.score(train)
            test_recs = run.records(test)
            test_score = float(sum(objectives.value(t.weights, r) for r in test_recs) / len(test_recs))
            done(name)
            per = [_row(run.store, x, recs) for x, recs in zip(test, test_recs)]  # one per test dataset
            c = test[0].as_dict()
            rows.append(
                {
                    "dataset": ",".join(d for d, _ in t.split.test),
                    "task": t.task,
                    "filter": name,
                    "label": f"{name} ({kind})",
                    "params": json.dumps(
                        {**c["filter_params"], **{k: v for k, v in params.items() if k.startswith("task.")}},
                        sort_keys=True,
                    ),
                    "tuned_on": t.split.tuned_on if kind == "tuned" else "defaults (not tuned)",
                    "tested_on": t.split.tested_on,
                    "objective": t.objective,
                    "trials": len(studies.complete(st)[: t.trials]) if kind == "tuned" else 0,
                    "train_score": train_score,
                    "test_score": test_score,
                    "overlap": f"OVERLAP: {t.split.overlap}" if t.split.overlap else "",
                    "runs": t.runs * len(test),
                    "seed": test[0].seed,
                    **_pooled(per),
                    "train_config_hashes": " ".join(config_hash(x.as_dict()) for x in train),
                    "test_config_hashes": " ".join(config_hash(x.as_dict()) for x in test),
                    "_test": test,
                    "_params": params,
                }
            )
    return rows + _measurements_row(t, run)


def _measurements_row(t: Tune, run: Runner) -> list[dict]:
    """The raw observations scored on the test data (the ``measurements`` row of ``replay eval``),
    where the task observes every position component directly: a filter worse than its input shows."""
    test = [
        t.config(d, p, t.split.test_seed if t.split.test_seed is not None else t.seed, "measurements", {}, {})
        for d, p in t.split.test
    ]
    if not observes_position(build_problem(test[0], 0, t.data_dir)):
        return []
    recs = run.records(test)
    score = float(sum(objectives.value(t.weights, r) for r in recs) / len(recs))
    return [
        {
            "dataset": ",".join(d for d, _ in t.split.test),
            "task": t.task,
            "filter": "measurements",
            "label": "measurements (raw observations)",
            "params": "{}",
            "tuned_on": "",
            "tested_on": t.split.tested_on,
            "objective": t.objective,
            "trials": 0,
            "train_score": "",
            "test_score": score if math.isfinite(score) else "",
            "overlap": f"OVERLAP: {t.split.overlap}" if t.split.overlap else "",
            "runs": t.runs * len(test),
            "seed": test[0].seed,
            **_pooled([_row(run.store, x, r) for x, r in zip(test, recs)]),
            "train_config_hashes": "",
            "test_config_hashes": " ".join(config_hash(x.as_dict()) for x in test),
            "_test": test,
            "_params": None,
        }
    ]


def _row(store, cfg: Config, recs) -> dict:
    """The leaderboard row (:func:`replay.scoring.summary.config_row`) of a configuration's stored records."""
    c, h = cfg.as_dict(), config_hash(cfg.as_dict())
    sha = {r.run: r.table_sha256 for r in recs}
    return summary.config_row(
        c,
        h,
        recs,
        lambda run_, cols: store.series(h, run_, cols, sha.get(run_)),
        (recs[0].version or "") if recs else "",
    )


def _pooled(rows) -> dict:
    """The test columns over the test datasets: means of ``pos_rmse``, ``pos_rmse_median`` and
    ``anees`` (one dataset: its own), sums of ``lost`` and ``diverged``."""

    def num(r, k):
        try:
            return float(r.get(k))
        except (TypeError, ValueError):
            return float("nan")

    out = {k: float(np.mean([num(r, k) for r in rows])) for k in ("pos_rmse", "pos_rmse_median", "anees")}
    out.update({k: int(sum(num(r, k) for r in rows if math.isfinite(num(r, k)))) for k in ("lost", "diverged")})
    if rows and all(r.get("still") for r in rows):  # issue 40: marked on the board (summary.marks)
        out["still"] = True
    for k in ("reference_input", "reference", "reference_shares", "unconstrained"):  # marks; the reference's
        if v := next((r[k] for r in rows if r.get(k)), ""):
            out[k] = v
    return out
