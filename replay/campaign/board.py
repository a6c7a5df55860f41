"""A campaign directory's leaderboard and paired comparisons; merging result directories.

Rows have the one schema of :mod:`replay.scoring.summary` (the same as ``replay eval``),
computed from the stored unit records. ``paired.csv``: ``dataset, task, a, b,
metric, n, diff, diff_ci95, a_better`` for every two configurations on the same
dataset and task (common random numbers): mean of a - b over the runs both
finished without divergence.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from replay.scoring import gap, summary
from replay.scoring.marks import marks
from replay.util.errors import ReplayError
from replay.util.files import write_csv

from . import index
from .store import Store
from replay.util.regular import read_bytes

PAIRED = ["dataset", "task", "a", "b", "metric", "n", "diff", "diff_ci95", "a_better"]


def _collect(store: Store):
    """(configs, records) of a campaign directory: {hash: config}, {hash: [records]}."""
    configs, records = {}, {}
    for h, cfg in store.configs():
        configs[h], records[h] = cfg, store.records(h)
    return configs, records


def campaign_rows(
    out, order=None, baseline: str | None = None, *, store: Store | None = None, collected=None
) -> list[dict]:
    """One leaderboard row per stored configuration of the campaign directory ``out``
    (:func:`replay.scoring.summary.config_row`, the schema of ``replay eval``), in ``order`` (config
    hashes, e.g. the campaign file's order) when given, else sorted; with paired columns.
    ``store``: the :class:`Store` of ``out`` that wrote the units (it keeps what it wrote);
    ``collected``: its ``(configs, records)`` (:func:`_collect`) when read already."""
    store = store or Store(out)
    configs, records = collected or _collect(store)
    rows = []
    for h, cfg in configs.items():
        recs = records[h]
        sha = {r.run: r.table_sha256 for r in recs}
        try:
            rows.append(
                summary.config_row(
                    cfg,
                    h,
                    recs,
                    lambda run, cols, h=h, sha=sha: store.series(h, run, cols, sha.get(run)),
                    (recs[0].version or "") if recs else "",
                )
            )
        except (KeyError, TypeError, ValueError, IndexError) as err:  # records edited by hand
            raise ReplayError(
                f"{store.units / h}: unit records lack what the leaderboard needs "
                f"({type(err).__name__}: {err}); remove the directory and run "
                "`replay campaign run` again"
            ) from None
    rows = [r for r in rows if r["runs"] or r["failed"]]
    names = index.names(store.out)  # a recording's id as its campaign file writes it, not a machine's path
    for r in rows:
        r["dataset"] = names.get(r["dataset"], r["dataset"])
    if order is not None:
        rank = {h: i for i, h in enumerate(order)}
        rows.sort(key=lambda r: (rank.get(r["config_hash"], len(rank)), r["config_hash"]))
    else:
        rows.sort(key=lambda r: (r["dataset"], r["task"], r["filter"], r["params"]))
    summary.label(rows)
    rows = gap.add_gap(summary.add_paired(rows, configs, records, baseline), configs, records)
    return summary.against_measurements(rows, configs, records)


def paired_rows(out, rows, metric_names=("pos_rmse", "ate"), *, collected=None) -> list[dict]:
    """Paired comparisons of every two configurations on one dataset and task (``rows``: the leaderboard)."""
    configs, records = collected or _collect(Store(out))
    return summary.paired_rows(rows, configs, records, metric_names)


columns = summary.columns
HEAD, TAIL = summary.HEAD, summary.TAIL


def _write(rows, path, cols):
    write_csv(rows, path, cols)


def summarise(out, order=None, store: Store | None = None) -> list[dict]:
    """Write ``leaderboard.csv`` and ``paired.csv`` into the campaign directory; return the rows.
    ``store``: the :class:`Store` that wrote the units (see :func:`campaign_rows`)."""
    out = Path(out)
    store = store or Store(out)
    collected = _collect(store)  # every unit read and checked once, for both files
    with np.errstate(all="ignore"):
        rows = campaign_rows(out, order, store=store, collected=collected)
        _write(rows, out / "leaderboard.csv", columns(rows))
        _write(paired_rows(out, rows, collected=collected), out / "paired.csv", PAIRED)
    return rows


def read_dir(d) -> list[dict]:
    """Leaderboard rows of a result directory: a campaign's units, else its ``leaderboard.csv``."""
    d = Path(d)
    if (d / "units").is_dir():
        with np.errstate(all="ignore"):
            return campaign_rows(d)
    path = d / "leaderboard.csv" if d.is_dir() else d
    if not path.is_file():
        raise ReplayError(f"{d}: no campaign units/ and no leaderboard.csv")
    rows = read_leaderboard(path)
    for row in rows:
        row.setdefault("label", row.get("filter", ""))
        for k, v in row.items():
            try:
                row[k] = float(v) if k not in HEAD + ["alignment", "version", "config_hash"] else v
            except (TypeError, ValueError):
                pass
    return rows


NEEDED = ("dataset", "task", "filter", "runs")  # in every leaderboard replay writes (eval, score -o, campaign)


def read_leaderboard(path: Path) -> list[dict]:
    """The rows of a leaderboard CSV, refused in one line naming it unless it is one: UTF-8 text whose
    header holds :data:`NEEDED` and at least one row (a trajectory, another CSV, a binary file would
    otherwise read as a table of NaN)."""
    what = "not a replay leaderboard (written by replay eval, replay score -o or replay campaign run)"
    try:
        text = read_bytes(path, "a leaderboard").decode("utf-8")
    except UnicodeDecodeError:
        raise ReplayError(f"{path}: {what}: not UTF-8 text") from None
    except OSError as e:
        raise ReplayError(f"{path}: cannot read ({e.strerror or e})") from None
    try:
        reader = csv.DictReader(io.StringIO(text, newline=""))
        rows = list(reader)
    except csv.Error as e:
        raise ReplayError(f"{path}: {what}: {str(e)[:80]}") from None
    lacking = [c for c in NEEDED if c not in (reader.fieldnames or [])]
    if lacking:
        raise ReplayError(f"{path}: {what}: its header lacks {', '.join(lacking)}")
    if not rows:
        raise ReplayError(f"{path}: an empty leaderboard (a header, no row)")
    if any(None in row or None in row.values() for row in rows):
        raise ReplayError(f"{path}: {what}: a row has more or fewer cells than the header")
    return rows


def merge(dirs, sort: str | None = None) -> list[dict]:
    """Rows of several result directories, optionally sorted by a metric; each row's ``source``
    is the directory (or leaderboard file) it came from, as given. A configuration is listed
    once per number of runs (the first directory that holds it with that many): a 5-run
    evaluation and a 50-run campaign of one configuration are two rows, told apart by
    ``source`` and ``runs``."""
    rows, seen = [], set()
    for d in dirs:
        for row in read_dir(d):
            key = (
                row.get("config_hash"),
                row.get("filter"),
                row.get("dataset"),
                row.get("task"),
                _num(row.get("runs")),
            )
            if key in seen:
                continue
            seen.add(key)
            rows.append({"source": str(d), **row})
    if sort:
        if rows and sort not in rows[0] and not any(sort in r for r in rows):
            known = ", ".join(k for k in columns(rows) if k.endswith(("_rmse", "ate", "err", "pct", "nees", "nis")))
            raise ReplayError(f"--sort {sort}: no such column (e.g. {known})")
        rows.sort(key=lambda r: (not np.isfinite(_num(r.get(sort))), _num(r.get(sort))))
    return rows


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def merged_columns(rows) -> list[str]:
    """The columns of a merged leaderboard: ``source``, then those of :func:`columns`."""
    return ["source"] + [c for c in columns(rows) if c != "source"]


def format_rows(rows) -> str:
    """A compact text table of the main columns (and first the source of merged rows)."""
    sourced = any("source" in r for r in rows)
    head = ["source"] * sourced + [
        "dataset",
        "task",
        "filter",
        "pos_rmse",
        "median",
        "ate",
        "anees",
        "diverged",
        "lost",
        "us/step",
        "reference",
    ]
    body = []
    for r in rows:
        pm, pc = _num(r.get("pos_rmse")), _num(r.get("pos_rmse_ci95"))
        body.append(
            [str(r.get("source", ""))] * sourced
            + [
                str(r.get("dataset", "")),
                str(r.get("task", "")),
                str(r.get("label") or r.get("filter")) + (" (not ranked)" if marks(r) else ""),
                f"{pm:.4f}" + (f" ±{pc:.4f}" if np.isfinite(pc) else ""),
                f"{_num(r.get('pos_rmse_median')):.4f}",
                f"{_num(r.get('ate')):.4f}",
                summary.consistency_cell(r, "anees"),
                f"{int(_num(r.get('diverged')) or 0)}/{int(_num(r.get('runs')) or 0)}",
                summary.lost_cell(r),
                f"{_num(r.get('us_per_step')):.1f}",
                str(r.get("reference") or "?") + (" (shares an input)" if r.get("reference_shares") else ""),
            ]
        )
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    fmt = lambda cells: "  ".join(
        c.ljust(w) if i < 3 + sourced else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths))
    )
    notes = [f"{r.get('label') or r.get('filter')}: not ranked: {m}" for r in rows for m in marks(r)]
    shared = sorted({(str(r.get("dataset")), str(r["reference_shares"])) for r in rows if r.get("reference_shares")})
    notes += [f"{d}: the reference shares a source with a fed input: {sh}" for d, sh in shared]
    free = sorted({(str(r.get("dataset")), str(r["unconstrained"])) for r in rows if r.get("unconstrained")})
    notes += [f"{d}: {line}" for d, lines in free for line in lines.split(" | ")]  # fusion_heading.py
    return "\n".join([fmt(head), *(fmt(b) for b in body), *notes])
