"""Trials of one estimator (rpg_trajectory_evaluation's ``--mul_trials``, evo_res over runs): several
estimate files or topics scored one by one and aggregated into one entry.

``replay score REF --trials 'orb=runs/orb_*.txt'`` (or ``replay.score(REF, trials={"orb": "runs/orb_*.txt"})``):
a trial set is ``[NAME=]SOURCE`` where SOURCE is a glob of files (``*``, ``?``, ``[...]``; matches in
natural order, ``run2`` before ``run10``), a glob of recordings with a topic (``runs/*.bag:/orb/pose``) or
one source; a NAME given several times collects its sources in that order. Without ``NAME=`` the name is
the glob's fixed part (``orb_*.txt`` -> ``orb``).

Each trial is scored as an estimate of its own (its leaderboard row with ``trial`` = 1..N) and the trials
are aggregated by :func:`replay.scoring.scorer.aggregate`, the aggregation of Monte Carlo runs: the
aggregated row (``trial`` empty, ``runs`` = N) holds, for every ``*_rmse`` metric and ``ate``,
``final_err``, ``drift_pct``, ``rpe_drift_pct``, ``nees`` (and per length the ``rel_<error>_rmse`` and
``rel_<error>_mean``), the mean over trials ``<m>``, its 95 % Student-t half-width ``<m>_ci95`` and the
median ``<m>_median``; ``lost`` = trials that lost the track (``--lost-threshold``; empty when not judged)
and ``lost_share`` as for filter runs.
"""

from __future__ import annotations

import glob
import json
import math
import os
import re
from contextlib import contextmanager

import numpy as np

from replay.util.canonical import config_hash
from replay.scoring import scorer
from replay.scoring.summary import lost_share
from replay.trajectory.io import RECORDING_SUFFIXES
from replay.util.errors import ReplayError

EXTRA = ("ate", "final_err", "drift_pct", "rpe_drift_pct", "nees")
GLOB = re.compile(r"[*?\[]")


def _natural(s: str):
    return [int(x) if x.isdigit() else x for x in re.split(r"(\d+)", s)]


def _default_name(pattern: str) -> str:
    path = pattern.split(":", 1)[0] if ":" in pattern else pattern
    stem = path.rsplit("/", 1)[-1]
    fixed = GLOB.split(stem, 1)[0].rstrip("_-.# ")
    if not fixed:
        fixed = stem.split(".", 1)[0] if not GLOB.search(stem.split(".", 1)[0]) else "trials"
    return fixed


def _expand(pattern: str, what: str) -> list[str]:
    """The sources of one pattern (module docstring)."""
    head, topic = pattern, ""
    for m in re.finditer(":", pattern):
        if pattern[: m.start()].lower().endswith(RECORDING_SUFFIXES):
            head, topic = pattern[: m.start()], pattern[m.start() :]
            break
    if not GLOB.search(head):
        return [pattern]
    found = sorted(glob.glob(head), key=_natural)
    if not found:
        raise ReplayError(f"{what}: no file matches {head!r}")
    return [f + topic for f in found]


def parse(specs, what: str = "--trials") -> dict:
    """``{name: [source, ...]}`` of ``[NAME=]SOURCE`` specs (module docstring)."""
    out = {}
    for spec in specs:
        spec = str(spec)
        name, _, rest = spec.partition("=")
        if not rest or "/" in name or ":" in name or GLOB.search(name) or not name.strip():
            name, rest = None, spec
        if not rest.strip():
            raise ReplayError(f"{what} {spec!r}: expected [NAME=]GLOB, e.g. orb=runs/orb_*.txt")
        sources = _expand(rest, f"{what} {spec}")
        out.setdefault((name or _default_name(rest)).strip(), []).extend(sources)
    return _once(out, what)


def not_reference(sets: dict, reference, what: str = "--trials") -> None:
    """Refuse a trial that is the reference itself (a glob such as ``*.tum`` catching ``gt.tum``)."""

    if not isinstance(reference, (str, os.PathLike)):
        return
    ref = os.path.realpath(os.fspath(reference))
    for name, sources in sets.items():
        for src in sources:
            if isinstance(src, (str, os.PathLike)) and os.path.realpath(os.fspath(src)) == ref:
                raise ReplayError(f"{what} {name}: {src} is the reference itself (narrow the glob)")


def _once(sets: dict, what: str) -> dict:
    for name, sources in sets.items():
        paths = [s for s in sources if isinstance(s, str)]
        if twice := [s for s in paths if paths.count(s) > 1]:
            raise ReplayError(f"{what} {name}: {twice[0]} is given twice (a trial counted twice would weigh double)")
    return sets


def parse_api(trials) -> dict:
    """``{name: [source, ...]}`` of ``replay.score(trials=...)``: None; a ``[NAME=]GLOB`` string; a list
    (one trial set: sources, globs, Trajectory objects or DataFrames); or ``{name: glob or list}``."""
    if trials is None:
        return {}
    if isinstance(trials, str):
        return parse([trials], "trials")
    if isinstance(trials, (list, tuple)):
        trials = {_default_name(str(trials[0])) if trials and isinstance(trials[0], str) else "trials": trials}
    if not isinstance(trials, dict):
        raise ReplayError(
            f"trials: expected a glob, a list of sources or {{name: glob or list}} (got {type(trials).__name__})"
        )
    out = {}
    for name, items in trials.items():
        items = [items] if isinstance(items, str) or not isinstance(items, (list, tuple)) else list(items)
        if not items:
            raise ReplayError(f"trials {name!r}: no trial")
        out[str(name)] = [
            s for it in items for s in (_expand(str(it), f"trials {name!r}") if isinstance(it, str) else [it])
        ]
    return _once(out, "trials")


def aggregated_keys(row: dict) -> list[str]:
    """The metrics of a trial row that are aggregated over trials (module docstring)."""
    return [
        k
        for k, v in row.items()
        if isinstance(v, (float, int))
        and not isinstance(v, bool)
        and (k.endswith("_rmse") or k in EXTRA or (k.startswith("rel_") and k.endswith(("_rmse", "_mean"))))
    ]


def aggregate(trial_rows: list[dict]) -> dict:
    """The aggregated row of the trial rows of one estimator (of one length, with ``--lengths``)."""
    if not trial_rows:
        raise ReplayError("trials: no trial to aggregate")
    keys = aggregated_keys(trial_rows[0])
    runs = [dict(r, diverged=False, us_per_step=math.nan) for r in trial_rows]
    agg = scorer.aggregate(runs, names=keys)
    first = trial_rows[0]
    row = {
        k: first[k]
        for k in ("dataset", "task", "filter", "label", "seed", "first", "alignment", "version")
        if k in first
    }
    for k in ("length", "length_m", "lengths_method"):
        if k in first:
            row[k] = first[k]
    judged = all(r.get("lost", "") != "" for r in trial_rows)
    row.update(
        runs=len(trial_rows),
        diverged=0,
        failed=0,
        trial="",
        lost=agg["lost"] if judged else "",
        lost_share=lost_share(trial_rows) if judged else math.nan,
    )
    row["params"] = json.dumps(
        {"trials": [json.loads(r["params"]).get("source", "") if r.get("params") else "" for r in trial_rows]},
        sort_keys=True,
    )
    for k in keys:
        vals = np.asarray([r.get(k, math.nan) for r in trial_rows], float)
        row[k], row[f"{k}_ci95"] = agg[k], agg[f"{k}_ci95"]
        row[f"{k}_median"] = float(np.nanmedian(vals)) if np.isfinite(vals).any() else math.nan
    row.update(
        scored=agg["scored"],
        masked=agg["masked"],
        us_per_step=math.nan,
        config_hash=config_hash({"trials": [r.get("config_hash", "") for r in trial_rows]}),
    )
    return row


def members(sets: dict) -> list[tuple]:
    """``[(score name, set name, trial number, source)]`` of ``{name: [source, ...]}``; score names ``NAME/k``."""
    return [(f"{name}/{k}", name, k, src) for name, srcs in sets.items() for k, src in enumerate(srcs, start=1)]


@contextmanager
def naming(member):
    """Errors of scoring the trial ``member`` (an item of :func:`members`; None: not a trial) name it."""
    try:
        yield
    except ReplayError as e:
        if member is None:
            raise
        raise ReplayError(f"trial {member[0]} ({member[3]}): {e}") from None


def mark(row: dict, name: str, k: int, source) -> dict:
    """A trial's leaderboard row: ``filter``/``label`` of the set, ``trial`` k, ``trial_source``."""
    row.update(filter=f"recorded:{name}", label=f"recorded:{name}", trial=k, trial_source=str(source))
    return row


def rows(trial_rows: list[dict]) -> list[dict]:
    """The rows of one trial set: each trial's rows (``trial`` = 1..N; one per length with ``--lengths``)
    and, per length (or once), the aggregated row after them."""
    out = list(trial_rows)
    groups = {}
    for r in trial_rows:
        groups.setdefault(r.get("length"), []).append(r)
    return out + [aggregate(g) for g in groups.values()]


def table(name: str, rows_: list[dict], relations, want_rpe: bool) -> str:
    """The printed block of one trial set: per trial and aggregated, the APE (RPE) rmse of each relation
    and, with lengths, the relative translation (%) and rotation (deg/m) rmse per length."""
    trials = [r for r in rows_ if r.get("trial") != ""]
    agg = [r for r in rows_ if r.get("trial") == ""]
    metrics = [f"ape_{rel}_rmse" for rel in relations if f"ape_{rel}_rmse" in agg[0]]
    metrics += [f"rpe_{rel}_rmse" for rel in relations if want_rpe and f"rpe_{rel}_rmse" in agg[0]]
    n = agg[0]["runs"]
    lost = agg[0].get("lost", "")
    out = [
        f"trials of {name}: {n}; lost {'not judged (--lost-threshold)' if lost == '' else f'{lost}/{n}'}; "
        "mean, median and 95 % t-interval over trials"
    ]
    blocks = [(None, agg[0], metrics)]
    blocks += [(a["length"], a, ["rel_trans_perc_rmse", "rel_rot_deg_per_m_rmse"]) for a in agg if "length" in a]
    for length, a, cols in blocks:
        these = [r for r in trials if r.get("length") == a.get("length")]
        if length is not None:
            out.append(f"length {length} = {a['length_m']:g} m")
        out.append(f"{'trial':>8}  {'source':<28}" + "".join(f"{c:>24}" for c in cols))
        for r in these:
            src = str(r.get("trial_source", ""))[-28:]
            out.append(f"{r['trial']:>8}  {src:<28}" + "".join(f"{r.get(c, math.nan):>24.6f}" for c in cols))
        for stat, suffix in (("mean", ""), ("median", "_median"), ("ci95 ±", "_ci95")):
            out.append(f"{stat:>8}  {'':<28}" + "".join(f"{a.get(c + suffix, math.nan):>24.6f}" for c in cols))
    return "\n".join(out) + "\n"
