"""A campaign file's ``[tune]`` table: ``replay tune`` at scale, for every dataset x task of the campaign.

::

    [tune]
    filters = ["ekf", "ukf", "pf"]      # default: the campaign's [[filter]] names
    trials = 50
    objective = "mean_rmse"             # as --objective
    split = { segment = 0.6 }           # or { seeds = 0 } (simulated data), or { train = [ids], test = [ids] }
    space = { "ukf.q_scale" = "log[1e-3, 1e2]", "pf.n_particles" = [100, 5000] }
    allow_overlap = false

``replay campaign run FILE`` checks the table with the rest of the file (before any unit),
runs the campaign's own configurations, then one tune per dataset x task (``segment``,
``seeds``; one tune for ``train``/``test``) into ``OUT/tune/<dataset>_<task>/`` (its
``study.db``, ``leaderboard.csv``, ``tuned.toml``), every tune's units in one store
``OUT/tune/units``: a configuration two tunes try is computed once. The runs, seed,
batch, alignment and data directory are the campaign's.
"""

from __future__ import annotations

import re

from replay.run.eval_options import DEFAULTS
from replay.util.errors import ReplayError

from . import check, run
from .options import TuneOptions


def plan(c, data_dir=None) -> list[tuple[str, run.Tune]]:
    """[(name, Tune)] of the campaign's ``[tune]`` table (none without one); one line naming the
    file, the line and the key on a bad table (its keys and their types: replay.campaign.spec.TUNE)."""
    tab = c.tune
    if not tab:
        return []
    names = tab.get("filters") or list(
        dict.fromkeys(
            cfg.filter for cfg in c.configs if not cfg.filter.startswith("recorded:") and cfg.filter != "measurements"
        )
    )
    entries = [
        (k, v, f"{c.path}:{c.where.line(k.split('.')[-1])}: [tune] space {k}") for k, v in tab.get("space", {}).items()
    ]
    split = tab.get("split")
    if split is None:
        raise c.where.error(
            "tune", "[tune] needs a split: { segment = 0.6 }, { seeds = S } or { train = [ids], test = [ids] }"
        )
    if set(split) - {"segment", "seeds", "train", "test"}:
        raise c.where.error("split", "expected { segment = 0.6 }, { seeds = S } or { train = [ids], test = [ids] }")
    common = dict(
        filters=names,
        entries=entries,
        trials=tab.get("trials", 50),
        objective=tab.get("objective", "mean_rmse"),
        runs=c.runs,
        allow_overlap=tab.get("allow_overlap", False),
        data_dir=data_dir or c.data_dir,
        alignment=c.configs[0].alignment if c.configs else DEFAULTS["alignment"],
        batch=c.batch,
    )
    prepare = lambda **given: check.prepare(TuneOptions(**given))  # the record of each tune, then checked
    out = []
    try:
        if "train" in split or "test" in split:
            ids = lambda side: ",".join(split.get(side) or []) if isinstance(split.get(side), list) else None
            out.append(("train-test", prepare(train=ids("train"), test=ids("test"), seed=c.seed, **common)))
            return out
        seen = set()
        for cfg in c.configs:
            key = (cfg.dataset, str(cfg.dataset_params), cfg.first, cfg.task, str(cfg.task_params))
            if key in seen or cfg.filter.startswith("recorded:"):
                continue
            seen.add(key)
            dp = {k: v for k, v in cfg.dataset_params.items() if k != "segment"}
            way = {"train_segment": str(split["segment"])} if "segment" in split else {"split": "seeds"}
            seed = split.get("seeds", c.seed)
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise c.where.error("split", f"seeds must be an integer >= 0 (got {seed!r})")
            t = prepare(
                dataset=cfg.dataset,
                task=cfg.task,
                task_params=cfg.task_params,
                dataset_params=dp,
                first=cfg.first,
                seed=seed,
                **way,
                **common,
            )
            name = re.sub(r"[^A-Za-z0-9._-]+", "_", f"{cfg.dataset}_{cfg.task}")
            while any(n == name for n, _ in out):
                name += "_"
            out.append((name, t))
    except ReplayError as err:
        if str(err).startswith(str(c.path)):
            raise
        raise ReplayError(f"{c.path}: [tune]: {err}") from None
    return out
