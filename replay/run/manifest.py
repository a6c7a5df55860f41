"""What an evaluation records about itself: its failures, the versions, the command line that repeats
it, the manifest."""

from __future__ import annotations

import json
import platform
import shlex
import sys

import numpy as np

from replay.data import registry
from replay.scoring.record import FAILED
from replay.util.version import __version__
from replay.filters import make_filter
from replay.filters.gating import per_filter
from replay.run.pipeline import plain
from replay.trajectory.recorded import RECORDED_PARAMS, is_recorded
from replay.tasks import make_task
import scipy


def failures(ev) -> dict:
    """``{filter: {"runs": [failed runs], "error": the first error}}`` of the filters that failed."""
    out = {}
    for res in ev.results:
        bad = [r for r in res.records if r.status == FAILED]
        if bad:
            out[res.name] = {"runs": [r.run for r in bad], "error": bad[0].error}
    return out


def versions() -> dict:
    return {
        "replay": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "platform": platform.platform(),
    }


def command_line(config: dict) -> str:
    """The ``replay eval`` command that repeats a configuration."""
    parts = [
        "replay",
        "eval",
        config["dataset"],
        "--task",
        config["task"],
        "--filters",
        ",".join(config["filters"]),
        "--runs",
        str(config["runs"]),
        "--seed",
        str(config["seed"]),
    ]
    if config.get("first"):
        parts += ["--first", str(config["first"])]
    if config.get("adapter"):
        parts += ["--adapter", config["adapter"]]
    if config.get("baseline"):
        parts += ["--baseline", config["baseline"]]
    if (config.get("dataset_params") or {}).get("mapping"):
        parts += ["--mapping", str(config["dataset_params"]["mapping"])]
    try:  # name only the dataset parameters that differ from their declared defaults
        defaults = plain(registry.check_params(config["dataset"], {}, adapter=config.get("adapter")))
    except Exception:  # noqa: BLE001 — a dataset no longer registered: name them all
        defaults = {}
    for key, value in (config.get("dataset_params") or {}).items():
        if key != "mapping" and (key not in defaults or defaults[key] != value):
            text = value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
            parts += ["--dataset-param", shlex.quote(f"{key}={text}")]
    try:  # the task parameters that differ from their declared defaults
        tdefaults = plain(make_task(config["task"]).params())
    except Exception:  # noqa: BLE001 — a task no longer registered: name them all
        tdefaults = {}
    for key, value in (config.get("task_params") or {}).items():
        if key not in tdefaults or tdefaults[key] != value:
            text = value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
            parts += ["--task-param", shlex.quote(f"{key}={text}")]
    for name, params in (config.get("filter_params") or {}).items():  # those that differ from the defaults
        try:
            defaults = (
                {p.name: p.default for p in RECORDED_PARAMS} if is_recorded(name) else plain(make_filter(name).params())
            )
        except Exception:  # noqa: BLE001 — a filter no longer registered: name them all
            defaults = {}
        for key, value in params.items():
            if key not in defaults or defaults[key] != value:
                text = value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))
                parts += ["-p", shlex.quote(f"{name}.{key}={text}")]
    return " ".join(parts)


def defaults_only(config: dict) -> bool:
    """Whether every filter and the task ran at their declared defaults (the command that repeats the
    run names no ``-p`` of a filter and no ``--task-param``; a recorded estimate's ``align`` is no
    tuning): its table says "defaults (not tuned)"."""
    parts = shlex.split(command_line(config))
    given = [v for k, v in zip(parts, parts[1:]) if k == "-p" and not v.startswith(("recorded:", "measurements."))]
    return not given and "--task-param" not in parts


def manifest(ev) -> dict:
    return {
        "config": ev.config,
        "command": command_line(ev.config),
        "argv": sys.argv,
        "versions": versions(),
        "dataset": ev.frame_meta,
        "adapter_report": ev.report,
        "units": ev.units,
        "results": {r.name: dict(r.summary) for r in ev.results},
        **({"failures": f} if (f := failures(ev)) else {}),
        **({"gating": g} if (g := per_filter(ev.results)) else {}),
    }
