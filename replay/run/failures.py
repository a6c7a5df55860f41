"""What a failed run records: the error of a filter (a plugin's bug, ``sys.exit``, an exhausted
memory, a broken protocol) as one line, and which errors end an evaluation instead.

A failure inside a filter is that filter's failed runs (``failed`` in the leaderboard, the
error in the manifest's ``failures``); the other filters' results stand. What ends an
evaluation is a user's error (:class:`replay.util.errors.ReplayError`, one line) in
``strict`` mode (``replay eval``), and an interrupt (Ctrl-C).
"""

from __future__ import annotations

import traceback

from replay.scoring.record import FAILED, RunRecord
from replay.util.errors import ProtocolError, ReplayError


def describe(err: BaseException) -> str:
    """One line: ``out of memory (...)``, ``the filter called sys.exit(0)``, or ``<Type>: <message>``."""
    if isinstance(err, MemoryError):
        text = f"out of memory ({type(err).__name__}: {err})" if str(err) else "out of memory"
    elif isinstance(err, SystemExit):
        text = f"the filter called sys.exit({err.code!r}) (SystemExit)"
    elif isinstance(err, ProtocolError):
        text = str(err)
    else:
        text = f"{type(err).__name__}: {err}"
    return (text.splitlines() or [""])[0][:500]


def failed(run: int, err: BaseException) -> RunRecord:
    """The record of a run that could not be computed."""
    return RunRecord(run, FAILED, error=describe(err), traceback="".join(traceback.format_exception(err))[-4000:])


def ends_run(err: BaseException, strict: bool) -> bool:
    """Whether an error raised by a filter is raised on (an interrupt; a user's error in
    ``strict`` mode) rather than recorded as the filter's failed runs."""
    if isinstance(err, (KeyboardInterrupt, GeneratorExit)):
        return True
    return strict and isinstance(err, ReplayError) and not isinstance(err, ProtocolError)
