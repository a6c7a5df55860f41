"""What the exports read from a `replay eval` output directory, and how they place it in space.

:func:`load_run` reads ``manifest.json`` and run 0 of ``estimates/<filter>.csv.gz``,
reloads the dataset named in the manifest (same adapter, mapping, ``first`` and, for
a simulator, the run-0 seed) and rebuilds the task problem for the reference. No
filter is run again.

East-north-up: exported poses are in the local ENU frame (frame id ``enu``). A task
names its position axes; :func:`enu_axes` maps ``x``/``east``, ``y``/``north``,
``z``/``up`` to themselves and ``depth``/``down`` to minus up, so that a
north-east-down task (dead reckoning: ``north, east, depth``) is not exported with
north as east. Its heading (clockwise from north) becomes the ENU yaw
(anticlockwise from east): ``yaw = pi/2 - heading`` (:func:`enu_yaw`). Axis names
outside that list are taken in order as x, y, z.
"""

from __future__ import annotations

import gzip
import json
import warnings
import zlib
from pathlib import Path

import numpy as np

from replay.trajectory.recorded import is_recorded
from replay.util import covcols
from replay.util.errors import DataError, ReplayError
from replay.util.regular import read_text
from replay.data import registry
from replay.tasks import make_task
from replay.util.seeds import DATA, TASK, rng_for
from replay.scoring import summary
from replay.campaign.store import RERUN_HINT, Store


def is_campaign(path) -> bool:
    """Whether ``path`` is a campaign's result directory (``units/``, no eval manifest)."""
    path = Path(path)
    return (path / "units").is_dir() and not (path / "manifest.json").exists()


def load_run(run_dir, data_dir=None, run: int = 0, select=None) -> dict:
    """``{config, frame, problem, estimates, run, source, manifest}`` of one run of an eval
    output directory (``select`` must be empty) or of a campaign (``select``: see
    :func:`load_campaign_run`). ``manifest``: the metadata to
    export, ``{file name: its text}``."""
    if is_campaign(run_dir):
        return load_campaign_run(run_dir, data_dir, run, select or {})
    if any((select or {}).values()):
        flags = ", ".join(f"--{k}" for k, v in select.items() if v)
        raise ReplayError(
            f"export: {flags} choose among a campaign's configurations; {run_dir} is a `replay eval` "
            "output (every filter of it is exported; --run picks the run)"
        )
    run_dir = Path(run_dir)
    path = run_dir / "manifest.json"
    try:
        text = path.read_text()
        cfg = json.loads(text)["config"]
        names, runs = list(cfg["filters"]), cfg.get("runs")
        cfg["dataset"], cfg["seed"], cfg["task"]  # noqa: B018 -- present
    except FileNotFoundError:
        raise DataError(
            path, "no such file: not a `replay eval` output directory (nor a campaign's: no units/)"
        ) from None
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise DataError(path, f"not a replay manifest ({e})") from None
    for name in names:
        if not isinstance(name, str) or not name or Path(name).name != name or name.startswith("."):
            raise DataError(path, f"filter name {name!r} is not a plain name")
    check_run(run, runs, path)
    frame, problem = frame_and_problem(cfg, run, data_dir)
    estimates = {
        name: read_estimates(run_dir / "estimates" / f"{name}.csv.gz", 0 if is_recorded(name) else run)
        for name in names
    }
    return {
        "config": cfg,
        "frame": frame,
        "problem": problem,
        "estimates": estimates,
        "run": run,
        "source": run_dir,
        "manifest": {"manifest.json": text},
    }


def check_run(run, runs, where) -> None:
    if isinstance(run, bool) or not isinstance(run, int) or run < 0 or (isinstance(runs, int) and run >= runs):
        have = f"runs 0 to {runs - 1}" if isinstance(runs, int) and runs > 0 else "no such run"
        raise ReplayError(f"{where}: --run {run}: it holds {have}")


def frame_and_problem(cfg: dict, run: int, data_dir=None):
    """The frame of ``run`` (a simulator draws it from the run's data stream) and the task problem
    rebuilt on the run's task stream, as the evaluation did."""
    dparams, tparams = dict(cfg.get("dataset_params") or {}), dict(cfg.get("task_params") or {})
    frame = registry.load_frame(
        cfg["dataset"],
        data_dir=data_dir,
        rng=rng_for(cfg["seed"], run, DATA),
        first=cfg.get("first"),
        adapter=cfg.get("adapter"),
        **dparams,
    )
    return frame, make_task(cfg["task"], **tparams).build(frame, rng_for(cfg["seed"], run, TASK))


def _split(value) -> list[str]:
    if not value:
        return []
    items = value if isinstance(value, (list, tuple)) else [value]
    return [x.strip() for item in items for x in str(item).split(",") if x.strip()]


def load_campaign_run(out, data_dir=None, run: int = 0, select=None) -> dict:
    """One run of the configurations of campaign directory ``out`` chosen by ``select``
    (``{dataset, task, filter, config}``: names, comma-separated lists; ``config``: hash
    prefixes). They must share the measurements (``replay.scoring.summary.group_key``); each is
    a track named by its leaderboard label (the filter, plus the parameters that differ).
    A configuration whose run is not stored (or damaged, or failed) is refused."""
    select, store = {k: _split(v) for k, v in (select or {}).items()}, Store(out)
    chosen = [
        (h, c)
        for h, c in store.configs()
        if (not select.get("dataset") or c["dataset"] in select["dataset"])
        and (not select.get("task") or c["task"] in select["task"])
        and (not select.get("filter") or c["filter"] in select["filter"])
        and (not select.get("config") or any(h.startswith(p) for p in select["config"]))
    ]
    if not chosen:
        asked = " ".join(f"--{k} {','.join(v)}" for k, v in select.items() if v) or "(all)"
        known = "; ".join(sorted({f"{c['dataset']} {c['task']} {c['filter']} {h[:8]}" for h, c in store.configs()}))
        raise ReplayError(f"{out}: no stored configuration matches {asked}; stored: {known or 'none'}")
    groups: dict = {}
    for h, c in chosen:
        groups.setdefault(summary.group_key(c), []).append((h, c))
    if len(groups) > 1:
        kinds = "; ".join(
            f"{g[0][1]['dataset']} task={g[0][1]['task']} seed={g[0][1]['seed']} "
            f"first={g[0][1]['first']} ({len(g)} configurations, e.g. --config {g[0][0][:8]})"
            for g in groups.values()
        )
        raise ReplayError(
            f"{out}: the selection spans {len(groups)} datasets/tasks ({kinds}); one export holds "
            "one: choose with --dataset, --task, --filter or --config"
        )
    chosen.sort(key=lambda hc: (hc[1]["filter"], json.dumps(hc[1]["filter_params"], sort_keys=True), hc[0]))
    rows = summary.label(
        [
            {"filter": c["filter"], "params": json.dumps(c["filter_params"], sort_keys=True, separators=(",", ":"))}
            for _, c in chosen
        ]
    )
    names = [r["label"].replace(" ", "") for r in rows]
    names = [n if names.count(n) == 1 else f"{n}@{h[:8]}" for n, (h, _) in zip(names, chosen)]
    check_run(run, None, out)
    estimates, manifest = {}, {}
    if (Path(out) / "campaign.toml").is_file():
        manifest["campaign.toml"] = read_text(Path(out) / "campaign.toml", "a campaign file")
    for name, (h, c) in zip(names, chosen):
        r = 0 if is_recorded(c["filter"]) else run
        unit = store.units / h
        rec, problem = Store._read_record(unit / f"{r}.json", r, h)  # checked as Store.scan does, one run only
        if problem is None and not rec.done:
            problem = (
                f"{unit / f'{r}.json'}: run {r} failed ({'no error recorded' if rec.error is None else rec.error})"
            )
        elif problem is None:
            problem = Store._check_table(unit / f"{r}.parquet", rec.table)[0]
        if problem is not None:
            stored = sorted(store.stored_runs(h, include_failed=False))
            hint = f"stored runs: {stored[0]} to {stored[-1]}" if stored else RERUN_HINT
            if not (unit / f"{r}.json").exists():
                problem = f"{unit}: run {r} of {name} is not stored"
            raise ReplayError(f"{problem}; {hint}")
        cols = store.series(h, r)
        nx = sum(1 for k in cols if k[:1] == "x" and k[1:].isdigit())
        P, full = covcols.matrices(cols, nx)
        estimates[name] = {
            "t": cols["t"],
            "x": np.column_stack([cols[f"x{i}"] for i in range(nx)]),
            "P": P,
            "full_covariance": full,
            "err": {k[4:]: v for k, v in cols.items() if k.startswith("err_")},
        }
        manifest[f"units/{h}/config.json"] = (unit / "config.json").read_text()
    cfg = chosen[0][1]
    frame, problem = frame_and_problem(cfg, run, data_dir or store.data_dirs().get(cfg["dataset"]))  # the campaign's
    for name, est in estimates.items():  # the position errors, in the task's axis order
        try:
            est["err"] = np.column_stack([est["err"][str(a)] for a in problem.axis_names])
        except KeyError as e:
            raise ReplayError(
                f"{out}: the table of {name} has no position error column err_{e.args[0]}; {RERUN_HINT}"
            ) from None
    manifest["selection"] = json.dumps({"run": run, "tracks": {n: h for n, (h, _) in zip(names, chosen)}})
    return {
        "config": cfg,
        "frame": frame,
        "problem": problem,
        "estimates": estimates,
        "run": run,
        "source": Path(out),
        "manifest": manifest,
    }


def _run_rows(fh, run: int):
    """The lines of one run: the writer puts each run's rows together, runs in order."""
    seen = False
    for line in fh:
        try:
            this = float(line.split(",", 1)[0])
        except ValueError:
            this = None  # let the parser name the bad row
        if this == run or (this is None and seen):
            seen = True
            yield line
        elif seen:
            return


def read_estimates(path, run: int = 0) -> dict:
    """``{t, x, P, err}`` of one run from an ``estimates/<filter>.csv.gz`` file.

    Only that run's rows are read (they are together in the file; the reading stops at
    the next run), so the memory does not grow with the number of runs.
    """
    try:
        with gzip.open(path, "rt") as fh:
            head = fh.readline().strip().split(",")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "input contained no data": refused below
                data = np.loadtxt(_run_rows(fh, run), delimiter=",", ndmin=2)
    except FileNotFoundError:
        raise DataError(path, "no such estimates file") from None
    except (OSError, ValueError, EOFError, zlib.error) as e:
        raise DataError(path, f"cannot read estimates ({e})") from None
    nx = sum(1 for h in head if h.startswith("x") and h[1:].isdigit())
    if not len(data) or data.shape[1] != len(head):
        raise DataError(
            path,
            f"no rows of run {run}" if not len(data) else f"{data.shape[1]} columns for the {len(head)} of the header",
        )
    if not np.array_equal(data[:, 1], np.arange(len(data))):
        raise DataError(path, f"the rows of run {run} are not its steps 0, 1, 2, ... in order")
    cols = dict(zip(head, data.T))
    missing = [h for h in ["t"] + [f"x{i}" for i in range(nx)] + covcols.variance_names(nx) if h not in cols]
    if missing:
        raise DataError(path, f"no column {missing[0]} in the header")
    P, full = covcols.matrices(cols, nx)
    err = [h for h in head if h.startswith("err_")]
    return {
        "t": cols["t"],
        "x": data[:, 3 : 3 + nx],
        "P": P,
        "full_covariance": full,
        "err": np.column_stack([cols[h] for h in err]) if err else np.zeros((len(data), 0)),
    }


def time_ns(frame, t) -> np.ndarray:
    """Absolute nanoseconds of frame times ``t``: meta t0_ns, else epoch, else 0, plus t."""
    t0 = frame.meta.get("t0_ns")
    if t0 is None:
        t0 = int(round(frame.epoch * 1e9)) if frame.epoch is not None else 0
    return int(t0) + np.round(np.asarray(t, float) * 1e9).astype(np.int64)


def heading_index(problem):
    """The state component holding the heading (or yaw), or None."""
    for name in ("heading", "yaw", "psi"):
        if name in problem.angle_index:
            return problem.angle_index[name]
    angles = getattr(problem.model, "x_angles", ())
    return angles[0] if len(angles) == 1 else None


def track_index(name: str, problem) -> tuple[list[int], int | None]:
    """(position components, heading component or None) of a track's state: the task's, or for a
    recorded estimate (``recorded:<name>``: its position only) the first d components."""
    if is_recorded(name):
        return list(range(len(problem.position_index))), None
    return list(problem.position_index), heading_index(problem)


_SLOT = {
    "x": (0, 1),
    "east": (0, 1),
    "y": (1, 1),
    "north": (1, 1),
    "z": (2, 1),
    "up": (2, 1),
    "depth": (2, -1),
    "down": (2, -1),
}


def enu_axes(problem) -> list[tuple[int, int]]:
    """(ENU slot, sign) of each position component of the task (see the module docstring)."""
    names = [str(a).lower() for a in problem.axis_names]
    if len(names) != len(problem.position_index) or not 1 <= len(names) <= 3:
        raise ReplayError(
            f"export: task with position axes {tuple(problem.axis_names)}: "
            "cannot place them in east-north-up (1 to 3 axes)"
        )
    slots = [_SLOT.get(n) for n in names]
    if None in slots or len({s for s, _ in slots}) < len(slots):
        return [(i, 1) for i in range(len(names))]
    return slots


def to_enu(p, axes) -> np.ndarray:
    """(n, 3) east-north-up positions from the task's position components ``p`` (n, d)."""
    p = np.asarray(p, float)
    out = np.zeros((len(p), 3))
    for i, (slot, sign) in enumerate(axes):
        out[:, slot] = p[:, i] if sign > 0 else -p[:, i]
    return out


def ned(problem) -> bool:
    """Whether the task's frame is north-east-down (its heading clockwise from north)."""
    return [str(a).lower() for a in problem.axis_names[:2]] == ["north", "east"]


def enu_yaw(heading, is_ned: bool):
    """ENU yaw (anticlockwise from east) of the task's heading."""
    return np.pi / 2 - heading if is_ned else heading
