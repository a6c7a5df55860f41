"""A smoothed track as a reference: one row of a `replay eval` output written as a TUM file that
``--reference FILE`` (the dataset parameter ``reference``, :mod:`replay.data.smoothed_reference`)
takes as the position reference of another evaluation of the same recording.

The file is a plain TUM trajectory (``t x y z qx qy qz qw``, readable by evo and ``replay score``)
whose ``#`` header says where it came from, one ``# key: value`` per line: the provenance line
printed above every table that uses it (``reference: smoothed, gtsam-batch over odom + gps``),
the dataset, its parameters, the task and the row's configuration. Times: seconds from the
recording's first sample (the frame's time plus the offset of a window or segment), so that a
second evaluation with other views finds the same instants. Positions: east-north-up in the
frame's local coordinates (the frame's reference convention); the orientation is the heading's
(yaw about up) where the task estimates one, else the identity. A 2-D task writes ``z = 0`` and
says ``dims: 2`` (the reference then has no height).
"""

from __future__ import annotations

import json

import numpy as np

from replay.scoring.provenance import fed_channels
from replay.outputs.run_data import enu_axes, enu_yaw, heading_index, load_run, ned, to_enu
from replay.util.errors import ReplayError
from replay.util.files import write_atomic
from replay.util.quat import from_yaw

SMOOTHERS = ("gtsam-batch", "gtsam-lag")


def provenance(name: str, inputs) -> str:
    """``smoothed, <row> over <input> + <input>``: the inputs by their mapping entry, in order."""
    entries = []
    for key in inputs:
        entry = str(key).split(".")[0]
        if key != "reference" and entry not in entries:
            entries.append(entry)
    kind = "smoothed" if name.split("+")[0] in SMOOTHERS or "+" in name else "estimated"
    return f"{kind}, {name} over " + (" + ".join(entries) if entries else "no input")


def choose(names, wanted: str | None, where) -> str:
    """The row to write: ``wanted``, or the output's only smoother row."""
    if wanted:
        if wanted not in names:
            raise ReplayError(f"{where}: no row {wanted!r} (rows: {', '.join(names)})")
        return wanted
    found = [n for n in names if n in SMOOTHERS or "+" in n]
    if len(found) != 1:
        raise ReplayError(f"{where}: name the row to write as a reference with --filter (rows: {', '.join(names)})")
    return found[0]


def write_reference(run_dir, path, name: str | None = None, run: int = 0, data_dir=None) -> tuple[int, str]:
    """Row ``name`` (default: the only smoother row) of run ``run`` of the eval output ``run_dir`` as
    a TUM file at ``path`` with its provenance header; (poses written, provenance line)."""
    loaded = load_run(run_dir, data_dir, run=run)
    cfg, problem, frame = loaded["config"], loaded["problem"], loaded["frame"]
    name = choose(list(loaded["estimates"]), name, run_dir)
    est = loaded["estimates"][name]
    x = np.asarray(est["x"], float)
    pos = to_enu(x[:, list(problem.position_index)], enu_axes(problem))
    h = heading_index(problem)
    q = from_yaw(enu_yaw(x[:, h], ned(problem))) if h is not None else np.tile([0.0, 0.0, 0.0, 1.0], (len(x), 1))
    offset = float(((frame.meta.get("view") or {}).get("offset_s")) or 0.0)
    t = np.asarray(est["t"], float) + offset
    ok = np.isfinite(pos).all(axis=1) & np.isfinite(t)
    if not ok.any():
        raise ReplayError(f"{run_dir}: row {name!r} has no finite position to write")
    line = provenance(name, getattr(problem, "inputs", {}) or {})
    header = {
        "replay": "reference track",
        "reference": line,
        "dataset": cfg["dataset"],
        "dataset_params": json.dumps(cfg.get("dataset_params") or {}, sort_keys=True),
        "task": cfg["task"],
        "task_params": json.dumps(cfg.get("task_params") or {}, sort_keys=True),
        "filter": name,
        "filter_params": json.dumps((cfg.get("filter_params") or {}).get(name, {}), sort_keys=True),
        "run": str(run),
        "seed": str(cfg.get("seed")),
        "time": "seconds from the recording's first sample",
        "frame": "east-north-up, the recording's local coordinates",
        "dims": str(len(problem.position_index)),
        "inputs": json.dumps(fed_channels(getattr(problem, "inputs", {}) or {}), sort_keys=True),
    }
    rows = np.column_stack([t, pos, q])[ok]
    body = "\n".join(" ".join(f"{v:.17g}" for v in r) for r in rows)
    write_atomic(path, "".join(f"# {k}: {v}\n" for k, v in header.items()) + body + "\n")
    return int(ok.sum()), line
