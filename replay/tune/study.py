"""The Optuna side of ``replay tune``: one study per filter in ``DIR/study.db`` (SQLite).

Determinism: trials run one after another, and the sampler that proposes trial n is a fresh
:class:`optuna.samplers.TPESampler` seeded from (``--seed``, filter, n) — n the number of
trials completed so far. What it proposes depends only on that seed and the completed trials,
so two tunes with one seed propose the same parameters, and a tune killed (even by
``kill -9``) and started again proposes what the uninterrupted one would: a trial left
``RUNNING`` by the kill is evaluated with the parameters it was given (its units already
stored are not computed again), one killed before all its parameters were stored is marked
failed and proposed again. ``optuna-dashboard DIR/study.db`` opens the studies.

Each study carries its configuration (``replay_fingerprint``: data, task, objective, space,
runs, seed); a study of the same name made by another configuration is refused in one line
before any trial.
"""

from __future__ import annotations

import json
import logging
import warnings
import zlib
from pathlib import Path

import numpy as np

from replay.util.errors import ReplayError

ATTR = "replay_fingerprint"
N_STARTUP = 10  # random trials before TPE models the history (Optuna's default)


def _optuna():
    import optuna

    optuna.logging.set_verbosity(logging.WARNING)
    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
    return optuna


def storage(out: Path):
    optuna = _optuna()
    return optuna.storages.RDBStorage(f"sqlite:///{(Path(out) / 'study.db').resolve()}")


def open_study(store, name: str, fingerprint: dict, where: Path):
    """The study ``name`` (created when new); refused when it belongs to another configuration."""
    optuna = _optuna()
    try:
        study = optuna.create_study(storage=store, study_name=name, direction="minimize", load_if_exists=True)
    except Exception as err:  # noqa: BLE001 — a damaged or foreign file: one line
        raise ReplayError(
            f"{where}: cannot open as an Optuna study ({type(err).__name__}: "
            f"{str(err).splitlines()[0] if str(err) else ''})"
        ) from None
    had = study.user_attrs.get(ATTR)
    if had is None:
        if study.trials:
            raise ReplayError(f"{where}: study {name!r} was not made by replay tune (no {ATTR}); use another --out")
        study.set_user_attr(ATTR, fingerprint)
    elif had != json.loads(json.dumps(fingerprint)):
        diff = sorted(
            k for k in set(had) | set(fingerprint) if had.get(k) != json.loads(json.dumps(fingerprint.get(k)))
        )
        raise ReplayError(
            f"{where}: study {name!r} belongs to another configuration (differs in: "
            f"{', '.join(diff)}); use another --out, or the options it was made with"
        )
    return study


def sampler_seed(seed: int, name: str, n: int) -> int:
    return int(np.random.SeedSequence([seed % 2**63, zlib.crc32(name.encode()), n]).generate_state(1)[0])


def next_trial(study, dims, seed: int, name: str, defaults: dict | None = None):
    """(trial, params): a trial left running by a kill (with all its parameters), else a new one;
    the first trial of a study is ``defaults`` when given."""
    optuna = _optuna()
    running = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,))
    want = {d.key: d.distribution() for d in dims}
    for t in running:
        if set(t.params) == set(want):
            return optuna.trial.Trial(study, t._trial_id), dict(t.params)
        study.tell(t.number, state=optuna.trial.TrialState.FAIL)  # killed while its parameters were stored
    n = len(complete(study))
    if defaults is not None and not study.get_trials(deepcopy=False):
        study.enqueue_trial(defaults)
    study.sampler = optuna.samplers.TPESampler(
        seed=sampler_seed(seed, name, n), n_startup_trials=N_STARTUP, multivariate=True
    )
    trial = study.ask(want)
    return trial, dict(trial.params)


def complete(study) -> list:
    optuna = _optuna()
    return sorted(study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,)), key=lambda t: t.number)


def best(study, trials: int):
    """The best of the first ``trials`` completed trials (the earliest among equals), or None."""
    done = complete(study)[:trials]
    return min(done, key=lambda t: (t.value, t.number)) if done else None
