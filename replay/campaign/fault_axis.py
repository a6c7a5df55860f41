"""A campaign's ``[[fault]]`` tables: injected faults on every dataset, and robustness sweeps.

::

    [[fault]]                 # on every [[dataset]] (beside a dataset's own params.fault)
    channel = "gps"
    kind = "outage"
    t0 = 120
    d = 60
    sweep = { d = [0, 30, 60, 120] }   # optional: one configuration per value (a robustness axis)

Each table is a fault of :mod:`replay.data.faults` (its ``channel``, ``kind`` and parameters,
checked by the same declarations, so a bad one is the API's and the CLI's line, with the file and
line in front). ``sweep`` names one parameter of the table and its values: every configuration
is repeated once per value (several sweeps: every combination), the fault entering the dataset
parameter ``fault`` and so the configuration hash, the leaderboard's ``view`` column and
``replay rerun`` as any fault does. :func:`replay.outputs.robustness` turns the rows of a sweep
into the degradation table and curves.
"""

from __future__ import annotations

import itertools

from replay.data import faults
from replay.util.errors import ReplayError
from replay.campaign.entries import _frame0

MAX_SWEEP = 1000


def variants(where, doc: dict) -> list[list[str]]:
    """The fault lists the campaign's configurations take, one per combination of the sweeps
    (``[[]]``: no ``[[fault]]``)."""
    tables = doc.get("fault", [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise where.error("fault", "expected [[fault]] tables (channel, kind, the kind's parameters, sweep)")
    choices = []
    for table in tables:
        table = dict(table)
        sweep = table.pop("sweep", None)
        if sweep is None:
            choices.append([_check(where, table)])
            continue
        if not isinstance(sweep, dict) or len(sweep) != 1:
            raise where.error("sweep", "expected sweep = { PARAMETER = [values] } (one parameter of the fault)")
        ((name, values),) = sweep.items()
        if not isinstance(values, list) or not 1 <= len(values) <= MAX_SWEEP:
            raise where.error("sweep", f"{name}: expected a list of 1 to {MAX_SWEEP} values")
        if name in table:
            raise where.error("sweep", f"{name} is given and swept: give it once")
        choices.append([_check(where, dict(table, **{name: v})) for v in values])
    return [list(c) for c in itertools.product(*choices)] or [[]]


def _check(where, table: dict) -> str:
    try:
        return faults.check(table)[0]
    except ReplayError as e:
        raise where.error("fault", str(e), table.get("channel")) from None


def with_faults(params: dict, extra: list[str]) -> dict:
    """A dataset's parameters with ``extra`` faults after its own."""
    if not extra:
        return params
    return dict(params, fault=list(params.get("fault") or []) + list(extra))


def check_frames(where, ds_entries, extras: list[list[str]], data_dir) -> None:
    """Run 0's frame of every dataset under every fault list, so that a fault on a channel the
    dataset lacks (or one that removes every sample) is refused before any unit, in one line."""
    for ds in ds_entries:
        for extra in extras:
            if not extra:
                continue
            try:
                _frame0(ds.id, with_faults(ds.params, extra), ds.first, data_dir)
            except ReplayError as e:
                raise where.error("fault", str(e), extra[0].split(":")[0]) from None
