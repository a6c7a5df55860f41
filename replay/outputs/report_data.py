"""What ``replay report`` reads: per dataset x task, every run of every configuration.

A :class:`Section` holds, per label, ``{run: series}`` with ``t``, ``pos`` (n, d) the
estimated position, ``ref`` (n, d) the reference (NaN where masked), ``err`` (n, d),
``valid`` (n,) and, from a campaign, ``nees``, ``nis``, ``nis_dof``; ``metrics`` holds the
per-run metrics (``pos_rmse``, and from a campaign every stored one) for the worst-run view
and the paired comparisons; ``sparse`` the labels of recorded estimates (``recorded:<name>``: a
position, stored as scored, i.e. after its ``align`` fit, only on the reference samples it was
associated with; NaN elsewhere, which is no masking of the reference). An eval directory stores no
reference: it is ``pos - err``, so a recorded estimate's is known only where it was associated
(``ref_sparse`` in its series); a campaign stores it (NaN only where masked). Every task keeps its
position in the first ``d`` state components (``Problem.position_index`` is ``(0, ..., d-1)``),
which is how ``pos`` is read.
"""

from __future__ import annotations

import csv
import gzip
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from replay.trajectory.recorded import is_recorded
from replay.util.errors import ReplayError
from replay.campaign import board, index
from replay.campaign.store import Store
from replay.campaign.board import read_dir


@dataclass
class Section:
    dataset: str
    task: str
    axes: tuple = ()
    runs: dict = field(default_factory=dict)  # label -> {run: series}
    metrics: dict = field(default_factory=dict)  # label -> {run: {metric: value}}
    rows: list = field(default_factory=list)  # leaderboard rows, in the leaderboard's order
    paired: list = field(default_factory=list)  # paired.csv rows of this dataset x task
    sparse: set = field(default_factory=set)  # labels of recorded estimates: NaN off their associated samples

    @property
    def title(self) -> str:
        return f"{self.dataset} / {self.task}"

    @property
    def labels(self) -> list[str]:
        return list(self.runs)


def _rmse(err) -> float:
    e = np.asarray(err, float)
    ok = np.isfinite(e).all(axis=1)
    return float(np.sqrt(np.mean(np.sum(e[ok] ** 2, axis=1)))) if ok.any() else float("nan")


def _series(t, pos, ref, err, extra=None) -> dict:
    s = {
        "t": np.asarray(t, float),
        "pos": pos,
        "ref": ref,
        "err": err,
        "valid": np.isfinite(ref).all(axis=1) & np.isfinite(err).all(axis=1),
    }
    s.update(extra or {})
    return s


def _unique(label: str, taken) -> str:
    if label not in taken:
        return label
    k = 2
    while f"{label} #{k}" in taken:
        k += 1
    return f"{label} #{k}"


def load_campaign(d: Path) -> list[Section]:
    store = Store(d)
    rows = board.read_dir(d)
    by_hash = {r.get("config_hash"): r for r in rows}
    sections: dict = {}
    names = index.names(d)  # as the leaderboard shows the dataset (a recording's id as written)
    for h, cfg in store.configs():
        done = [r for r in store.records(h) if r.done]
        if not done:
            continue
        ds = names.get(cfg["dataset"], cfg["dataset"])
        sec = sections.setdefault((ds, cfg["task"]), Section(ds, cfg["task"]))
        row = by_hash.get(h)
        lab = _unique(str(row.get("label") if row else cfg["filter"]), sec.runs)
        if row is not None:
            row["label"] = lab
            sec.rows.append(row)
        runs, mets = {}, {}
        for rec in done:
            raw = store.series(h, rec.run)
            axes = tuple(k[4:] for k in raw if k.startswith("ref_"))
            ref = np.column_stack([raw[f"ref_{a}"] for a in axes])
            err = np.column_stack([raw[f"err_{a}"] for a in axes])
            pos = np.column_stack([raw[f"x{j}"] for j in range(len(axes))])
            runs[rec.run] = _series(
                raw["t"], pos, ref, err, {k: np.asarray(raw[k], float) for k in ("nees", "nis", "nis_dof") if k in raw}
            )
            mets[rec.run] = {k: v for k, v in rec.metrics.items() if isinstance(v, (int, float))}
            mets[rec.run].setdefault("pos_rmse", _rmse(err))
            sec.axes = sec.axes or axes
        sec.runs[lab], sec.metrics[lab] = runs, mets
        if is_recorded(cfg["filter"]):
            sec.sparse.add(lab)
    rank = {id(r): i for i, r in enumerate(rows)}
    for sec in sections.values():  # the leaderboard's order (dataset, task, filter, parameters)
        sec.rows.sort(key=lambda r: rank[id(r)])
        order = {str(r.get("label")): i for i, r in enumerate(sec.rows)}
        sec.runs = dict(sorted(sec.runs.items(), key=lambda kv: order.get(kv[0], len(order))))
    _attach_paired(d, sections)
    return [sections[k] for k in sorted(sections)]


def load_eval(d: Path) -> list[Section]:
    rows = read_dir(d)
    try:
        cfg = json.loads((d / "manifest.json").read_text())["config"]
        key = (cfg["dataset"], cfg["task"])
    except (OSError, KeyError, TypeError, json.JSONDecodeError):
        key = (rows[0].get("dataset", "?"), rows[0].get("task", "?")) if rows else ("?", "?")
    sec = Section(*key)
    for r in rows:
        r.setdefault("label", r.get("filter"))
    sec.rows = [r for r in rows if (r.get("dataset"), r.get("task")) == key] or rows
    for path in sorted((d / "estimates").glob("*.csv.gz")):
        with gzip.open(path, "rt") as fh:
            head = fh.readline().strip().split(",")
            data = np.loadtxt(fh, delimiter=",", ndmin=2)
        col = {name: data[:, i] for i, name in enumerate(head)}
        name = path.name[: -len(".csv.gz")]
        extra = {"ref_sparse": True} if is_recorded(name) else None  # its reference: where it was associated
        axes = tuple(h[4:] for h in head if h.startswith("err_"))  # the position axes, in order
        sec.axes = sec.axes or axes
        runs, mets = {}, {}
        for r in np.unique(col["run"]):
            sel = col["run"] == r
            pos = np.column_stack([col[f"x{j}"][sel] for j in range(len(axes))])
            err = np.column_stack([col[f"err_{a}"][sel] for a in axes])
            runs[int(r)] = _series(col["t"][sel], pos, pos - err, err, extra)
            mets[int(r)] = {"pos_rmse": _rmse(err)}
        sec.runs[name], sec.metrics[name] = runs, mets
        if is_recorded(name):
            sec.sparse.add(name)
    order = {str(r.get("label")): i for i, r in enumerate(sec.rows)}
    sec.runs = dict(sorted(sec.runs.items(), key=lambda kv: order.get(kv[0], len(order))))
    sec.paired = _paired_columns(sec.rows)
    return [sec] if sec.runs else []


def _paired_columns(rows) -> list[dict]:
    """paired.csv-like rows from an eval leaderboard's ``pos_rmse_vs_<baseline>`` columns."""
    out = []
    for r in rows:
        for k, v in r.items():
            if k.startswith("pos_rmse_vs_") and not k.endswith("_ci95") and v not in ("", None):
                out.append(
                    {
                        "dataset": r.get("dataset"),
                        "task": r.get("task"),
                        "a": str(r.get("label")),
                        "b": k[len("pos_rmse_vs_") :],
                        "metric": "pos_rmse",
                        "n": r.get("runs"),
                        "diff": v,
                        "diff_ci95": r.get(f"{k}_ci95"),
                    }
                )
    return out


def _attach_paired(d: Path, sections: dict) -> None:
    path = d / "paired.csv"
    if not path.is_file():
        return
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            sec = sections.get((row.get("dataset"), row.get("task")))
            if sec is not None:
                sec.paired.append(row)


def load(d: Path) -> list[Section]:
    """The sections of a campaign directory or a ``replay eval`` output directory."""
    d = Path(d)
    if (d / "units").is_dir():
        sections = load_campaign(d)
    elif (d / "estimates").is_dir():
        sections = load_eval(d)
    else:
        raise ReplayError(
            f"{d}: not a result directory (no units/ from `replay campaign run`, no estimates/ from `replay eval`)"
        )
    if not sections:
        raise ReplayError(f"{d}: no finished runs to report")
    return sections


def worst_run(sec: Section):
    """The run with the highest median (over the configurations) position RMSE, or None with one run."""
    common = set.intersection(*(set(m) for m in sec.metrics.values())) if sec.metrics else set()
    if len(common) < 2:
        return None
    score = {}
    for r in sorted(common):
        v = np.array([sec.metrics[lab][r].get("pos_rmse", np.nan) for lab in sec.metrics], float)
        if np.isfinite(v).any():
            score[r] = float(np.median(v[np.isfinite(v)]))
    return max(score, key=score.get) if score else None
