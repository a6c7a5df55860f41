"""``replay rerun MANIFEST``: repeat a recorded ``replay eval`` and check every recorded result.

A manifest is accepted only when it can be trusted to describe a run
(:func:`load`), checked before any computation, each problem one line naming
the manifest and the key:

* its schema: ``config`` and ``results`` objects with every key the rerun needs,
  each of its type (``runs`` an integer >= 1, ``filters`` a non-empty list of
  distinct names, ``filter_params`` an object per filter, ...);
* each filter's configuration hash, recomputed from the recorded configuration
  (:func:`replay.run.pipeline.config_hash`), equals the recorded one
  (``config.config_hashes`` and the result's ``config_hash``): an edited
  configuration is not the one whose numbers are recorded;
* it names no code to import (:func:`check_sources`): each filter, the task and the
  adapter is a built-in, an installed entry point (``replay.filters``, ...) or a name
  of this session; a ``package.module:Class`` name is refused, before anything is
  imported, unless its module is allowed (``replay rerun --allow-module package.module``);
* every filter of ``config.filters`` has its recorded result and no other filter
  has one, with its RMSE values (numbers), and the columns that repeat the
  configuration (``dataset``, ``task``, ``filter``, ``params``, ``seed``, ``first``,
  ``alignment``) agree with it;
* the dataset's checksum is recorded (``dataset_sha256``, 64 hex digits); it may
  be null only for a simulated dataset, which the simulator and its recorded
  parameters identify.

:func:`repeat` runs the configuration again (:func:`replay.run.evaluation.evaluate`),
and :func:`verify` compares: the same dataset checksum, the same configuration
(every key of :data:`CONFIG` but the checksum and hashes, compared on their own, and
the ``baseline`` of the paired columns, null for the first filter),
the same configuration hashes, and each filter's whole leaderboard row
(:mod:`replay.scoring.summary`): the same set of columns and every value equal to the
recorded one — results (RMSEs, ``ate``, ``lost``, ``lost_share``, ``diverged``,
``failed``, ``nees``, ``nis``, ``final_err``, ``drift_pct``, medians, ``*_ci95``,
ANEES/ANIS and their flags, ``scored``, ``masked``, the paired columns, ...) and the
columns that repeat the configuration — except :data:`NOT_COMPARED`: timing
(``us_per_step``), the package ``version`` and ``rerun_rtol`` (an earlier
version's note). Any parameter that changes a result therefore fails the rerun even when
the manifest's hashes were recomputed after editing it: the rerun of the edited
configuration does not give the recorded numbers. (An edit that changes no recorded
number, such as a ``lost_threshold`` that classifies every run as before, is
reproduced: the recorded numbers are then those of the edited configuration too.)

Values are compared exactly (NaN equals NaN; a count is no float) for every filter: the
filters are bit-reproducible, the swarm filters of paper 002 included (each run draws from
its own seeded streams; two processes, with one and with two threads, give the same bits
for every registered filter), so a rerun says "reproduced" only when every recorded value is equal, and a
manifest with one RMSE changed by 1 % (or by one unit in the last place) is refused. A
``rerun_rtol`` that an earlier version recorded beside a swarm filter's row is not compared
and loosens nothing.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from replay.run.eval_options import BY_NAME as EVAL
from replay.run.pipeline import Config, config_hash, is_sim
from replay.trajectory.recorded import is_recorded
from replay.scoring.summary import TIMING
from replay.util.errors import ReplayError
from replay.util.regular import read_text
from replay.util.tomlfile import MAX_DEPTH, depth
from replay.util.plugins import refuse_unallowed
from replay.run.evaluation import evaluate

SHA256 = re.compile(r"^[0-9a-f]{64}$")
HASH = re.compile(r"^[0-9a-f]{16}$")
_NUM = (int, float)
NOT_COMPARED = frozenset(TIMING) | {"version", "rerun_rtol"}  # not compared (rerun_rtol: older manifests)
ECHOES = ("dataset", "task", "filter", "seed", "first", "alignment")  # row columns that repeat the configuration


def _is(value, kinds) -> bool:
    """``isinstance`` that keeps bools out of the numbers."""
    if isinstance(value, bool) and bool not in kinds:
        return False
    return isinstance(value, kinds)


RUN_OPTIONS = ("runs", "seed", "first", "alignment", "divergence_threshold")  # replay.run.eval_options
# key: (accepted types, may be null, description for the message)
CONFIG = {
    "dataset": ((str,), False, "a dataset id or path"),
    "task": ((str,), False, "a task name"),
    "task_params": ((dict,), False, "an object of task parameters"),
    "filters": ((list,), False, "a list of filter names"),
    "filter_params": ((dict,), False, "an object of parameters per filter"),
    "runs": ((int,), False, EVAL["runs"].accepts()),
    "seed": ((int,), False, EVAL["seed"].accepts()),
    "first": ((int,), True, EVAL["first"].accepts()),
    "dataset_params": ((dict,), False, "an object of dataset parameters"),
    "adapter": ((str,), True, "an adapter name or null"),
    "alignment": ((str,), False, EVAL["alignment"].accepts()),
    "divergence_threshold": (_NUM, True, EVAL["divergence_threshold"].accepts()),
    "dataset_sha256": ((str,), True, "64 hex digits (null only for a simulated dataset)"),
    "config_hashes": ((dict,), False, "an object of configuration hashes per filter"),
}


def load(path, allow_modules=()) -> dict:
    """The manifest at ``path``, checked (module docstring); raises a one-line :class:`ReplayError`.

    ``allow_modules``: modules a ``module:Class`` name of the manifest may import (:func:`check_sources`)."""
    path = Path(path)
    raw = read_text(path, "a replay manifest", limit=1 << 30)  # a regular file (a FIFO would block), UTF-8
    if not raw.strip():
        raise ReplayError(f"{path}: empty file, not a replay manifest")
    try:
        man, deep = json.loads(raw), False
    except ValueError as err:
        raise ReplayError(f"{path}: not a replay manifest (not valid JSON: {str(err).splitlines()[0]})") from None
    except RecursionError:  # too deep for the parser
        man, deep = None, True
    if deep or depth(man) > MAX_DEPTH:
        raise ReplayError(f"{path}: not a replay manifest (objects or arrays nested more than {MAX_DEPTH} deep)")
    check(man, path, allow_modules)
    return man


def check(man, path, allow_modules=()) -> None:
    """Refuse, in one line, a manifest that cannot be trusted (module docstring)."""

    def bad(key, what):
        return ReplayError(f"{path}: {key}: {what}")

    if not isinstance(man, dict):
        raise ReplayError(f"{path}: not a replay manifest (a JSON {type(man).__name__}, not an object)")
    for key in ("config", "results"):
        if key not in man:
            raise bad(key, "missing: not a replay manifest")
        if not isinstance(man[key], dict):
            raise bad(key, f"expected an object, got {type(man[key]).__name__}")
    cfg, results = man["config"], man["results"]
    for key, (kinds, nullable, what) in CONFIG.items():
        if key not in cfg:
            raise bad(f"config.{key}", f"missing (expected {what})")
        value = cfg[key]
        if not (value is None and nullable) and not _is(value, kinds):
            raise bad(f"config.{key}", f"expected {what}, got {type(value).__name__} {value!r:.60}")
    for key in RUN_OPTIONS:  # the declarations replay eval checked them with
        try:
            EVAL[key].check(cfg[key])
        except ReplayError:
            raise bad(f"config.{key}", f"expected {EVAL[key].accepts()}, got {cfg[key]!r:.60}") from None
    filters = cfg["filters"]
    if not filters:
        raise bad("config.filters", "empty: no filter to repeat")
    for name in filters:
        if not isinstance(name, str) or not name:
            raise bad("config.filters", f"expected filter names, got {name!r}")
    if len(set(filters)) != len(filters):
        raise bad("config.filters", f"a filter is listed twice ({', '.join(filters)})")
    baseline = cfg.get("baseline")  # recorded since the paired columns are compared; null: the first filter
    if baseline is not None and baseline not in filters:
        raise bad("config.baseline", f"{baseline!r:.60} is not among config.filters ({', '.join(filters)})")
    check_sources(cfg, path, allow_modules)
    extra = sorted(set(results) - set(filters))
    if extra:
        raise bad(
            "results",
            f"{', '.join(map(str, extra))} not among config.filters ({', '.join(filters)}): "
            "a result the rerun would not check",
        )
    for key in ("filter_params", "config_hashes"):
        extra = sorted(set(cfg[key]) - set(filters))
        if extra:
            raise bad(f"config.{key}", f"{', '.join(extra)} not among config.filters ({', '.join(filters)})")
    _check_dataset(cfg, bad)
    for name in filters:
        _check_filter(cfg, results, name, bad)


def check_sources(cfg: dict, path, allow_modules=()) -> None:
    """Refuse a manifest whose filter, task or adapter is a ``module:attribute`` name of a
    module not in ``allow_modules``: resolving it would import that module (run its code).

    Built-in names, installed entry points (their distributions were installed by the user)
    and names registered in this session are resolved without such a name; nothing is
    imported here. A manifest received from elsewhere thus runs only code already chosen."""
    named = [("config.filters", "filter", n) for n in cfg["filters"] if not is_recorded(n)]
    named += [("config.task", "task", cfg["task"]), ("config.adapter", "adapter", cfg["adapter"])]
    for key, kind, name in named:
        refuse_unallowed(name, allow_modules, f"{path}: {key}", kind, "a rerun")


def _check_filter(cfg: dict, results: dict, name: str, bad) -> None:
    if name not in cfg["filter_params"]:
        raise bad(f"config.filter_params.{name}", "missing: the filter's parameters are not recorded")
    if not isinstance(cfg["filter_params"][name], dict):
        raise bad(
            f"config.filter_params.{name}", f"expected an object, got {type(cfg['filter_params'][name]).__name__}"
        )
    recorded = cfg["config_hashes"].get(name)
    if not isinstance(recorded, str) or not HASH.match(recorded):
        raise bad(f"config.config_hashes.{name}", f"expected 16 hex digits, got {recorded!r}")
    config = Config(
        cfg["dataset"],
        cfg["dataset_params"],
        cfg["first"],
        cfg["task"],
        cfg["task_params"],
        name,
        cfg["filter_params"][name],
        cfg["seed"],
        cfg["alignment"],
        cfg["divergence_threshold"],
        cfg["adapter"],
    )
    actual = config_hash(config.as_dict())
    if actual != recorded:
        raise bad(
            f"config.config_hashes.{name}",
            f"{recorded} does not match the recorded configuration "
            f"(which hashes to {actual}): the manifest was edited or damaged",
        )
    res = results.get(name)
    if res is None:
        raise bad(f"results.{name}", "missing: the filter's recorded results are not in the manifest")
    if not isinstance(res, dict):
        raise bad(f"results.{name}", f"expected an object, got {type(res).__name__}")
    if res.get("config_hash") != recorded:
        raise bad(
            f"results.{name}.config_hash", f"{res.get('config_hash')!r} is not the configuration's hash {recorded}"
        )
    _check_echoes(cfg, res, name, bad)
    expected = ["pos_rmse"] + [k[:-5] for k in res if k.endswith("_rmse_ci95")]  # each mean beside its interval
    for key in expected:
        if key not in res:
            raise bad(f"results.{name}.{key}", "missing: the recorded RMSE values are incomplete")
    for key, value in res.items():
        if key.endswith("_rmse") and not _is(value, _NUM):
            raise bad(f"results.{name}.{key}", f"expected a number, got {type(value).__name__} {value!r:.40}")


def _check_echoes(cfg: dict, res: dict, name: str, bad) -> None:
    """The result's columns that repeat the configuration agree with it (a hand edit of one side)."""
    wants = {key: (name if key == "filter" else cfg[key]) for key in ECHOES}
    wants["first"] = cfg["first"] or ""  # as the leaderboard writes it
    wants["params"] = json.dumps(cfg["filter_params"][name], sort_keys=True, separators=(",", ":"))
    for key, want in wants.items():
        if key in res and res[key] != want:  # a deleted column is found by the rerun
            where = {"filter": "config.filters", "params": f"config.filter_params.{name}"}.get(key, f"config.{key}")
            raise bad(
                f"results.{name}.{key}",
                f"{res[key]!r:.80} does not repeat {where} ({want!r:.80}): the manifest was edited or damaged",
            )


def _check_dataset(cfg: dict, bad) -> None:
    sha = cfg["dataset_sha256"]
    try:
        simulated = is_sim(cfg["dataset"])
    except ReplayError as err:
        raise bad("config.dataset", str(err)) from None
    if sha is None:
        if not simulated:
            raise bad(
                "config.dataset_sha256",
                f"null, but {cfg['dataset']} is not a simulated dataset: without "
                "its checksum the rerun cannot tell whether the data changed",
            )
    elif not SHA256.match(sha):
        raise bad("config.dataset_sha256", f"expected 64 lowercase hex digits, got {sha!r:.80}")


def repeat(man: dict, data_dir=None, progress=None):
    """Run the manifest's configuration again: the :class:`replay.run.evaluation.Evaluation`.

    ``progress``: a :class:`replay.util.progress.Progress` told of each run done (as ``replay eval``'s)."""
    cfg = man["config"]
    return evaluate(
        cfg["dataset"],
        task=cfg["task"],
        filters=cfg["filters"],
        runs=cfg["runs"],
        seed=cfg["seed"],
        first=cfg["first"],
        data_dir=data_dir,
        task_params=cfg["task_params"],
        filter_params=cfg["filter_params"],
        dataset_params=cfg["dataset_params"],
        adapter=cfg["adapter"],
        alignment=cfg["alignment"],
        divergence_threshold=cfg["divergence_threshold"],
        baseline=cfg.get("baseline"),
        progress=progress,
    )


def differences(man: dict, ev) -> list[str]:
    """What the rerun ``ev`` did not reproduce of the manifest ``man`` (empty: everything):
    the dataset checksum, the configuration, the hashes and every compared column (module docstring)."""
    cfg, out = man["config"], []
    if cfg["dataset_sha256"] != ev.config.get("dataset_sha256"):
        out.append(f"dataset checksum {cfg['dataset_sha256']} -> {ev.config.get('dataset_sha256')}")
    again = _as_written(ev.config)
    for key in [*CONFIG, "baseline"]:
        if key not in ("dataset_sha256", "config_hashes") and again.get(key) != cfg.get(key):
            out.append(f"config.{key}: {_show(cfg.get(key))} -> {_show(again.get(key))}")
    for r in ev.results:
        was = man["results"][r.name]
        if r.config_hash != cfg["config_hashes"][r.name]:
            out.append(
                f"{r.name}: configuration {cfg['config_hashes'][r.name]} -> {r.config_hash} "
                f"(this version fills in other parameters)"
            )
        new = {k: v for k, v in _as_written(r.summary).items() if k not in NOT_COMPARED}
        old = {k: v for k, v in was.items() if k not in NOT_COMPARED}
        for k in sorted(set(new) - set(old)):
            out.append(f"{r.name}.{k}: not recorded (deleted from the manifest?) -> {_show(new[k])}")
        for k in sorted(set(old) - set(new)):
            out.append(f"{r.name}.{k}: {_show(old[k])} -> not computed")
        for k in [k for k in old if k in new]:  # in the leaderboard's order: the headline columns first
            if not same(old[k], new[k]):
                out.append(f"{r.name}.{k}: {_show(old[k])} -> {_show(new[k])}")
    return out


def same(recorded, rerun) -> bool:
    """Whether a rerun's value equals the recorded one: two numbers of equal value (NaN equals
    NaN; a bool is no number), anything else equal and of one type."""
    if _is(recorded, _NUM) and _is(rerun, _NUM):
        return recorded == rerun or (recorded != recorded and rerun != rerun)
    return type(recorded) is type(rerun) and recorded == rerun


def _as_written(obj):
    """``obj`` as the manifest records it (JSON, as :func:`replay.outputs.files.write_all` writes it)."""
    return json.loads(json.dumps(obj, default=str))


def _show(value) -> str:
    """A value for the one-line verdict (strings quoted, long values cut)."""
    text = repr(value) if isinstance(value, str) else str(value)
    return text if len(text) <= 80 else text[:77] + "..."


def verify(man: dict, ev, path) -> None:
    """Raise a one-line :class:`ReplayError` unless ``ev`` reproduces the manifest exactly."""
    diff = differences(man, ev)
    if diff:
        more = (
            f" (and {len(diff) - 5} more: {', '.join(d.partition(':')[0] for d in diff[5:])})" if len(diff) > 5 else ""
        )
        raise ReplayError(f"{path}: not reproduced: " + "; ".join(diff[:5]) + more)
