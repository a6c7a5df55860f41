"""``--rate``, ``--window``, ``--segment``, ``--fault``: shorthand for the view dataset parameters
(:mod:`replay.data.views`, :mod:`replay.data.faults`).

``replay eval D --rate 1`` is ``replay eval D --dataset-param rate=1``; both at once are refused.
``--fault SPEC`` (repeatable) is ``--dataset-param 'fault=["SPEC", ...]'``.
"""

from __future__ import annotations

import click

from replay.util.errors import ReplayError

OPTIONS = (
    (
        "--rate",
        "rate",
        float,
        "Resample the dataset onto a regular grid at HZ (per channel the sample nearest each "
        "grid point within half a period, else masked; nothing averaged or invented). Same as --dataset-param rate=HZ.",
    ),
    (
        "--window",
        "window",
        str,
        "Keep START:END seconds from the first sample (either bound may be empty), or "
        "#I:J sample indices; times start again at 0. Same as --dataset-param window=START:END.",
    ),
    (
        "--segment",
        "segment",
        str,
        "Keep the share A:B of the duration (e.g. 0:0.6 for the first 60 %), after "
        "--window. Same as --dataset-param segment=A:B.",
    ),
)


FAULT_HELP = (
    "Inject a sensor fault before the task (never into the reference), repeatable: "
    "CHANNEL:KIND:NAME=VALUE,..., e.g. gps:outage:t0=120,d=60 (docs/robustness.md lists the kinds). "
    "Same as --dataset-param 'fault=[\"SPEC\"]'."
)


def fault_option(command):
    """``--fault SPEC`` (repeatable; keyword argument ``fault``, a tuple)."""
    return click.option("--fault", "fault", multiple=True, metavar="SPEC", help=FAULT_HELP)(command)


def view_options(command):
    """The options on a click command (keyword arguments ``rate``, ``window``, ``segment``, ``fault``)."""
    for flag, name, kind, text in reversed(OPTIONS):
        command = click.option(flag, name, default=None, type=kind, metavar=name.upper(), help=text)(command)
    return fault_option(command)


def with_views(dataset_params: dict, rate=None, window=None, segment=None, fault=()) -> dict:
    """``dataset_params`` with the views given as options (checked later with the dataset's parameters)."""
    out = dict(dataset_params)
    for (flag, name, _, _), value in (*zip(OPTIONS, (rate, window, segment)), (("--fault", "fault", 0, 0), fault)):
        if value is None or value == ():
            continue
        if name in out:
            raise ReplayError(f"{flag} {value} and --dataset-param {name}={out[name]}: give the view once")
        out[name] = list(value) if name == "fault" else value
    return out
