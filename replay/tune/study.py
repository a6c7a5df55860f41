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

A damaged ``study.db`` (not an SQLite file, a page that fails SQLite's ``quick_check``, an
Optuna table missing, a trial row that does not read back, a completed trial without its value
or its parameters) is refused in one line naming the file, before Optuna writes to it, and is
never repaired in place. What it held can be recomputed from the units: move it aside and run the
same command again. The trials are replayed (the same seed proposes the same parameters from the
same completed trials) and each trial's runs are read from ``units/`` (:mod:`replay.campaign.store`
checks them; a damaged unit is computed again), so only the study is rebuilt. The file is not
moved automatically: it may be recoverable (``sqlite3 study.db .recover``), and the command run
next may not be the one that made it.
"""

from __future__ import annotations

import json
import logging
import sqlite3
import warnings
import zlib
from pathlib import Path

import numpy as np

from replay.util.errors import ReplayError
from urllib.parse import quote
import optuna

ATTR = "replay_fingerprint"
N_STARTUP = 10  # random trials before TPE models the history (Optuna's default)


def _optuna():
    optuna.logging.set_verbosity(logging.WARNING)
    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
    return optuna


TABLES = ("studies", "study_user_attributes", "trials", "trial_params", "trial_values", "version_info")


def damaged(path: Path, why, units=None) -> ReplayError:
    """The one line for a damaged ``study.db`` at ``path``: what is wrong and how to recompute it."""
    if isinstance(why, BaseException):
        text = str(why).splitlines()[0].removeprefix("(sqlite3.DatabaseError) ") if str(why) else ""
        why = f"{type(why).__name__}: {text}" if text else type(why).__name__
    units = Path(units) if units is not None else path.parent
    return ReplayError(
        f"{path}: damaged, not a readable replay tune study ({why}); to recompute it from {units / 'units'}, "
        f"move it aside (mv {path} {path}.damaged) and run the same command (replay tune or campaign run) "
        "again: its trials are replayed from the stored units (only a missing or damaged unit is computed again)"
    )


def check_file(path: Path, units=None) -> None:
    """Refuse a damaged ``study.db`` (module docstring) before Optuna opens it; an absent file is a
    new study. Only read (a hot journal of a killed writer is rolled back, as SQLite always does)."""
    path = Path(path)
    if not path.exists():
        return

    try:
        # read-write, not read-only: a journal left hot by a killed tune is rolled back (SQLite's own
        # recovery, what Optuna's next open does); a read-only connection would call it damaged
        con = sqlite3.connect(f"file:{quote(str(path.resolve()))}?mode=rw", uri=True)
        try:
            ok = con.execute("PRAGMA quick_check").fetchone()[0]
            tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        finally:
            con.close()
    except sqlite3.Error as err:
        if "locked" in str(err) or "busy" in str(err):
            raise ReplayError(f"{path}: locked by another process ({err}); close it (optuna-dashboard?)") from None
        raise damaged(path, err, units) from None
    if ok != "ok":
        raise damaged(path, f"SQLite quick_check: {ok}", units)
    missing = [t for t in TABLES if t not in tables]
    if missing:
        raise damaged(path, "no Optuna table " + ", ".join(missing), units)


def storage(out: Path, units=None):
    """The Optuna storage of ``out/study.db`` (checked first, :func:`check_file`; ``units``: the
    directory holding ``units/``, named in the refusal)."""
    path = Path(out) / "study.db"
    check_file(path, units)
    optuna = _optuna()
    try:
        return optuna.storages.RDBStorage(f"sqlite:///{path.resolve()}")
    except Exception as err:  # noqa: BLE001 — SQLAlchemy or Optuna refusing the file: one line
        raise damaged(path, err, units) from None


def read_back(study, keys, where: Path, units=None):
    """``study`` with every trial read back (a row that does not parse, a completed trial without
    a value or with other parameters than ``keys``: :func:`damaged`)."""
    optuna = _optuna()
    try:
        trials = study.get_trials(deepcopy=False)
        attrs = study.user_attrs
    except Exception as err:  # noqa: BLE001 — a damaged row: one line
        raise damaged(where, err, units) from None
    for t in trials:
        if t.state == optuna.trial.TrialState.COMPLETE:
            if not isinstance(t.value, (int, float)):
                raise damaged(where, f"study {study.study_name!r}: trial {t.number} is complete without a value", units)
            if keys is not None and set(t.params) != set(keys):
                raise damaged(where, f"study {study.study_name!r}: trial {t.number} lacks its parameters", units)
    return attrs


def open_study(store, name: str, fingerprint: dict, where: Path, units=None):
    """The study ``name`` (created when new); refused when it belongs to another configuration or
    does not read back (:func:`read_back`)."""
    optuna = _optuna()
    try:
        study = optuna.create_study(storage=store, study_name=name, direction="minimize", load_if_exists=True)
    except Exception as err:  # noqa: BLE001 — a damaged or foreign file: one line
        raise damaged(where, err, units) from None
    had = read_back(study, None, where, units).get(ATTR)
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
    read_back(study, fingerprint.get("space"), where, units)  # its trials have this space's parameters
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
