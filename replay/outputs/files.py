"""Outputs of an evaluation: the printed table, leaderboard CSV, estimates, manifest.

The leaderboard has the one schema of :mod:`replay.scoring.summary` (the campaign's):
one row per dataset x task x filter, with the paired columns against the
baseline filter (the first listed unless ``--baseline`` names one).

The files are written as one set (:func:`write_all`): into a staging directory
beside the output directory, then moved into place in one step
(:class:`replay.util.output_set.OutputSet`), so that a full disk, a kill or an error
leaves the previous set or the new one, never a mix. An existing output
directory is replaced only when it is a whole ``replay eval`` output (its marker,
or a replay manifest and nothing else); it must not be, hold or lie inside an
input (:func:`check_output`).
"""

from __future__ import annotations

import csv
import gzip
import io
import json
import os
from pathlib import Path

import numpy as np

from replay.run.evaluation import Evaluation
from replay.run.manifest import defaults_only, manifest
from replay.scoring.summary import (
    MIN_SCORED_SHARE,
    SYNTHETIC,
    columns,
    consistency_cell,
    lost_cell,
    scored_cell,
    scored_share,
)
from replay.util import covcols
from replay.data import dataset_ref
from replay.util.errors import ReplayError
from replay.util.files import write_atomic, write_csv
from replay.util.lock import held, holder
from replay.util.output_set import OutputSet
from replay.util.staging import is_report_dir
from replay.scoring import gap, outages, provenance
from replay.scoring.marks import marks
from replay.scoring.scorer import rmse_over_time


def leaderboard_rows(ev: Evaluation) -> list[dict]:
    """The evaluation's leaderboard rows (:mod:`replay.scoring.summary`), in ``--filters`` order."""
    return ev.rows


def deterministic_row(row, metrics) -> bool:
    """Whether a row's runs are one run: several runs, and every metric's interval that is a number
    exactly 0 (:func:`replay.scoring.scorer.deterministic`: equal up to rounding, 1e-12 relative)."""
    cis = [row.get(f"{k}_ci95", np.nan) for k in metrics]
    cis = [c for c in cis if isinstance(c, (int, float)) and np.isfinite(c)]
    return row["runs"] > 1 and bool(cis) and all(c == 0 for c in cis)


def _mark_cell(row) -> str:
    """The table's mark of a row that is not a filter's error (:func:`replay.scoring.summary.marks`)."""
    tags = (["still"] if str(row.get("still")) == "True" else []) + (
        ["ref=input"] if row.get("reference_input") else []
    )
    return f" ({', '.join(tags)})" if tags else ""


def format_table(ev: Evaluation) -> str:
    """The table ``replay eval`` prints."""
    rows = leaderboard_rows(ev)
    metrics = [k for k in columns(rows) if k.endswith("_rmse")]
    recorded = any(str(r["filter"]).startswith("recorded:") for r in rows)  # evo users compare the ATE
    head = (
        ["filter"]
        + metrics[:1]
        + ["median"]
        + (["ate"] if recorded else [])
        + metrics[1:]
        + ["anees", "us/step", "diverged", "lost", "scored"]
    )
    minimum = ev.config.get("min_scored_share", MIN_SCORED_SHARE.default)
    body, warnings = [], []
    for row in rows:
        cells = [row["filter"] + _mark_cell(row)]
        warnings += [f"{row['filter']}: not ranked: {m}" for m in marks(row)]
        same = deterministic_row(row, metrics)
        for k in metrics:
            v, c = row.get(k, np.nan), row.get(f"{k}_ci95", np.nan)
            cells.append(f"{v:.4f}" + (f" ±{c:.4f}" if np.isfinite(c) and not same else ""))
            if k == metrics[0]:
                cells.append(f"{row.get('pos_rmse_median', np.nan):.4f}")
                if recorded:
                    cells.append(f"{row.get('ate', np.nan):.4f}")
        cells += [
            consistency_cell(row, "anees"),
            f"{row['us_per_step']:.1f}",
            f"{row['diverged']}/{row['runs']}",
            lost_cell(row),
            scored_cell(row, minimum),
        ]
        body.append(cells)
        if same:
            warnings.append(
                f"{row['filter']}: deterministic: 1 distinct run (the {row['runs']} runs are identical up to "
                "rounding; interval 0)"
            )
        if scored_share(row) < minimum:
            warnings.append(
                f"{row['filter']}: scored on {row['scored']} of {row['scored'] + row['masked']} reference "
                f"samples ({scored_cell(row, 0)}; the rest masked), under min_scored_share={minimum:g}: "
                "its numbers describe only the samples scored"
            )
    widths = [max(len(str(x)) for x in col) for col in zip(head, *body)]
    line = lambda cells: "  ".join(
        str(c).rjust(w) if i else str(c).ljust(w) for i, (c, w) in enumerate(zip(cells, widths))
    )
    cfg = ev.config
    rule = ", ".join(
        f"{k}={cfg['task_params'][k]:g}" for k in ("lost_threshold", "lost_steps") if k in cfg["task_params"]
    )
    title = f"{cfg['dataset']}  task={cfg['task']}  runs={cfg['runs']}  seed={cfg['seed']}" + (
        f"  first={cfg['first']}" if cfg["first"] else ""
    )
    title += "".join("\n" + line for line in provenance.header(ev.frame_meta.get("reference")))
    if defaults_only(cfg):
        title += "\nfilters: defaults (not tuned; replay tune tunes them)"
    worse = [
        f"{r['label']} (+{r['worse_than_measurements_by']} m)"
        for r in ev.rows
        if r.get("worse_than_measurements") is True
    ]
    if worse:
        title += (
            "\nworse than its own measurements (the measurements row: the raw observations, scored "
            "alike; paired over runs, ± the 95 % interval): " + ", ".join(worse)
        )
    if any(r.get("measurements") == SYNTHETIC for r in ev.rows):
        title += (
            f"\nsynthetic measurements: task {cfg['task']} draws them from the reference plus its own "
            "noise, not from the recording's sensors (task fusion reads the sensors)"
        )
    unit = ev.units or {}
    shown = ", ".join(f"{k} {unit[k]}" for k in metrics if k in unit)
    note = (
        "RMSE: mean over runs of per-run RMSE, ± half-width of the 95 % interval; median: "
        f"median over runs of the position RMSE ({unit.get('pos_rmse', 'm')})\n"
        f"units: {shown}{', ' if shown else ''}us/step µs per step (1 = dimensionless)\n"
        + (
            "ate: position RMSE after the --alignment fit (evo's APE with -a); a recorded estimate with an "
            "align (mapping or -p recorded:NAME.align=se3) is scored after that fit, its numbers before it in "
            "the *_unaligned columns\n"
            if recorded
            else ""
        )
        + "anees: mean position NEES over runs and steps (about the number of position axes if "
        "consistent: judged against the 95 % band of that mean, runs x steps x axes degrees of freedom over "
        "the NEES's time correlation; 'collapsed' when the covariance has shrunk to nothing)\n"
        f"diverged: numerical failure (left out of the means); lost: the track was lost "
        f"(position error above lost_threshold m for lost_steps samples: {rule or 'not judged'}; "
        "kept in the means); * = lost runs make up most of the mean\n"
        "scored: share of the reference samples scored (the rest masked); ! = under min_scored_share "
        f"({minimum:g})"
    )
    return "\n".join([title, line(head), *(line(b) for b in body), *gap.lines(rows), *warnings, note])


def write_leaderboard(rows: list[dict], path: Path) -> None:
    write_csv(rows, path, columns(rows))


def write_estimates(ev: Evaluation, out: Path) -> None:
    """Per filter: ``estimates/<filter>.csv.gz`` (every run, every step) and the RMSE-over-time curve."""
    est_dir = out / "estimates"
    est_dir.mkdir(parents=True, exist_ok=True)
    for r in ev.results:
        nx = r.estimates[0].x.shape[1]
        pidx = ev.position_components(r.name)
        head = ["run", "k", "t"] + [f"x{i}" for i in range(nx)] + covcols.variance_names(nx)
        head += [f"err_{axis}" for axis in ev.axis_names] + covcols.covariance_names(pidx)
        with (
            open(est_dir / f"{r.name}.csv.gz", "wb") as raw,
            gzip.GzipFile(fileobj=raw, mode="wb", compresslevel=6, mtime=0) as gz,
            io.TextIOWrapper(gz, newline="") as fh,
        ):  # mtime 0: the same run gives the same bytes; level 6: 9's size +0.5 % in 55 % of its time (measured)
            fh.write(",".join(head) + "\n")
            for run, (est, err) in enumerate(zip(r.estimates, r.errors)):
                n = len(est.x)
                block = np.column_stack(
                    [
                        np.full(n, run),
                        np.arange(n),
                        ev.t[:n],
                        est.x,
                        np.diagonal(est.P, axis1=1, axis2=2),
                        err["position"],
                        *covcols.covariance_columns(est.P, pidx).values(),
                    ]
                )
                np.savetxt(fh, block, delimiter=",", fmt="%.10g")
        curve = rmse_over_time([e["position"] for e in r.errors])
        np.savetxt(
            est_dir / f"{r.name}_rmse_over_time.csv",
            np.column_stack([ev.t, curve]),
            delimiter=",",
            header="t,pos_rmse_across_runs",
            comments="",
            fmt="%.10g",
        )


RUNS_HEAD = ["dataset", "task", "filter", "params", "config_hash", "run", "status"]


def run_rows(ev: Evaluation) -> list[dict]:
    """One row per filter and run: the configuration's columns, the run, its status and every
    per-run metric (the rows ``replay.campaign_results(out, runs=True)`` returns)."""
    rows = []
    for r in ev.results:
        params = json.dumps(r.params, sort_keys=True, separators=(",", ":"))
        for rec in r.records:
            rows.append(
                {
                    "dataset": ev.config["dataset"],
                    "task": ev.config["task"],
                    "filter": r.name,
                    "params": params,
                    "config_hash": r.config_hash,
                    "run": rec.run,
                    "status": rec.status,
                    **(rec.metrics or {}),
                }
            )
    return rows


def write_runs(ev: Evaluation, path: Path) -> None:
    """``runs.csv``: :func:`run_rows`, floats written in full (``repr``: they read back bit for bit)."""
    rows = run_rows(ev)
    cols = RUNS_HEAD + [k for k in dict.fromkeys(k for row in rows for k in row) if k not in RUNS_HEAD]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: repr(v) if isinstance(v, float) else v for k, v in row.items()})
    write_atomic(path, buf.getvalue())


KIND = "replay eval"  # the kind recorded in the output directory's ownership marker


def legacy_output(path: Path) -> bool:
    """Whether ``path`` is a ``replay eval`` output written before ownership markers: a replay
    manifest, the leaderboard, estimates (and a ``replay report``) and nothing else."""
    try:
        man = json.loads((path / "manifest.json").read_text())
    except (OSError, ValueError):
        return False
    if not (isinstance(man, dict) and "config" in man and "results" in man):
        return False
    for e in path.iterdir():
        if e.name in ("leaderboard.csv", "manifest.json") and e.is_file() or is_report_dir(e):
            continue
        if (
            e.name == "estimates"
            and e.is_dir()
            and not e.is_symlink()
            and all(f.is_file() and f.name.endswith((".csv.gz", "_rmse_over_time.csv")) for f in e.iterdir())
        ):
            continue
        return False
    return True


CLAIM = ".replay-claim"  # in a numbered directory being computed: its process's pid, locked (outputs/rundirs.py)


def claim_holder(path) -> int | None:
    """The pid of the live process computing into ``path`` (a directory holding only its claim;
    -1 when the pid is not yet written), None if it is not a claimed directory or its process died."""
    try:
        if os.listdir(path) != [CLAIM]:
            return None
    except OSError:
        return None
    pid = holder(Path(path) / CLAIM)
    if pid == str(os.getpid()):
        return os.getpid()
    if not held(Path(path) / CLAIM):
        return None
    return int(pid) if pid.isdigit() else -1


def refuse_claimed(path, what: str = "--out") -> None:
    """Refuse (one line naming its pid) a directory another live process has claimed."""
    pid = claim_holder(path)
    if pid is not None and pid != os.getpid():
        raise ReplayError(
            f"{what} {path}: another replay eval process (pid {pid if pid > 0 else 'unknown'}) "
            f"is computing into it; choose another {what}"
        )


def owned(path: Path) -> bool:
    """The ownership test of a directory without a marker (:func:`check_output`): a ``replay eval``
    output written before markers, or a directory holding only a claim of this process or of a
    dead one. Another live process's claim is refused in one line naming its pid."""
    refuse_claimed(path)
    try:
        return os.listdir(path) == [CLAIM] or legacy_output(path)
    except OSError:
        return False


def eval_inputs(dataset: str, data_dir=None, mapping=None) -> list[Path]:
    """The files ``replay eval DATASET`` reads: the dataset file or bag directory (a plain path, or
    a registered file dataset where it is found), and the topic mapping."""
    return dataset_ref.resolve(dataset).inputs(data_dir, mapping)


def check_output(out, inputs=(), what: str = "--out") -> Path:
    """Before computing: refuse (one line) an output directory that is, holds or lies inside an
    input, is not writable, is on a read-only or full file system, or exists and is not a whole
    ``replay eval`` output (:meth:`OutputSet.check`). Returns it resolved."""
    check_name_lengths(out, what)
    refuse_claimed(out, what)
    return output_set(out, inputs, what).check()


def check_location(out, inputs=(), what: str = "--out") -> Path:
    """:func:`check_output` but for the contents: for a numbered directory about to be claimed."""
    check_name_lengths(out, what)
    return OutputSet(out, what=what, inputs=inputs).check(contents=False)


def output_set(out, inputs=(), what: str = "--out") -> OutputSet:
    """The :class:`OutputSet` of a ``replay eval`` output directory: an existing one is replaced only
    when its marker names :data:`KIND`, or it is an output of before markers, or a dead run's claim."""
    return OutputSet(out, KIND, what=what, inputs=inputs, legacy=owned)


def check_name_lengths(out, what: str = "output", room: int = 17) -> None:
    """Refuse a path with a component longer than the file system allows (NAME_MAX; the last one
    less ``room`` characters for the staging name ``.<name>.staging-<pid>``) or too long as a whole."""
    p = Path(os.path.abspath(out))
    probe = next((q for q in p.parents if os.path.isdir(q)), Path("/"))
    try:
        name_max, path_max = os.pathconf(probe, "PC_NAME_MAX"), os.pathconf(probe, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    shown = str(out) if len(str(out)) <= 60 else f"{str(out)[:40]}...{str(out)[-12:]}"
    for i, part in enumerate(p.parts):
        limit = name_max - (room if i == len(p.parts) - 1 else 0)
        if len(os.fsencode(part)) > limit:
            raise ReplayError(
                f"{what} {shown}: a name of {len(os.fsencode(part))} bytes ({part[:20]}...); at most {limit} fit here"
            )
    if len(os.fsencode(str(p))) + 64 > path_max:
        raise ReplayError(
            f"{what} {shown}: the path is {len(os.fsencode(str(p)))} bytes; at most "
            f"{path_max - 64} fit here (with the files written inside)"
        )


def write_all(ev: Evaluation, out: Path, *, what: str = "output") -> dict:
    """Leaderboard, estimates and manifest into ``out``, as one set; returns the paths written.

    The set is written into a staging directory and moved into place in one step; the previous
    set (if ``out`` holds one) is replaced only as a whole. The dataset file and mapping of ``ev``
    are inputs: ``out`` may not be, hold or lie inside them.
    """
    out = Path(out)
    mapping = (ev.config.get("dataset_params") or {}).get("mapping")
    check_output(out, [ev.frame_meta.get("path"), mapping], what)
    with output_set(out, [ev.frame_meta.get("path"), mapping], what).staged() as stage:
        write_leaderboard(leaderboard_rows(ev), stage / "leaderboard.csv")
        write_estimates(ev, stage)
        write_runs(ev, stage / "runs.csv")
        write_atomic(stage / "manifest.json", json.dumps(manifest(ev), indent=2, default=str))
        outages.write(ev, stage)  # fusion score=outages: outages.csv, outages_summary.csv
    return {
        "leaderboard": out / "leaderboard.csv",
        "manifest": out / "manifest.json",
        "estimates": out / "estimates",
        "runs": out / "runs.csv",
    }


def readable_name(dataset: str) -> str:
    """A directory name for a dataset: a registered id with ``/`` as ``_`` (``bohai_20220822_0_6``),
    a file or bag directory by its name without suffix (``ROS_example``)."""
    p = Path(dataset)
    if p.exists() or p.suffix.lower() in (".csv", ".bag", ".mcap", ".db3", ".log", ".txt"):
        name = p.name if p.is_dir() else p.stem
    else:
        name = dataset.replace("/", "_").replace("\\", "_")
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name).strip("._") or "dataset"
