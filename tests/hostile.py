"""Helpers for the corpus of malformed and hostile inputs (``tests/test_hostile_*.py``).

Every case asserts one of two outcomes: a **refusal** (exit status 2, exactly one
non-empty line on stderr naming what is wrong, no traceback; the heartbeat of a slow
load, ``load FILE: 3 s``, is progress, not part of the error, and is left out) or a **counted repair**
(the command succeeds and the adapter's report counts what it dropped or repaired).
``CORPUS`` collects the case ids of every module so that a test can count them.
"""
from __future__ import annotations

import re

from click.testing import CliRunner

from replay.cli import main

CORPUS: set[str] = set()
# a line of the load heartbeat (replay.util.progress.Loading): printed on stderr when reading a file takes
# over 3 s (a loaded machine), beside any error
PROGRESS = re.compile(r"^load .+: (\d+ s(, .*)?|(done|stopped) in \d+ s)$")


def message_lines(stderr: str) -> list[str]:
    """The non-empty lines of ``stderr`` that are not load progress: an error must be exactly one."""
    return [ln for ln in stderr.splitlines() if ln.strip() and not PROGRESS.match(ln.strip())]


def register(*ids: str) -> None:
    """Record corpus case ids (call at import time of each ``test_hostile_*`` module)."""
    CORPUS.update(ids)


def invoke(args, *, cwd=None, env=None):
    """``replay ARGS`` in process (CliRunner, stderr kept apart)."""
    runner = CliRunner()
    if cwd is not None:
        import os

        old = os.getcwd()
        os.chdir(cwd)
        try:
            return runner.invoke(main, [str(a) for a in args], env=env, catch_exceptions=True)
        finally:
            os.chdir(old)
    return runner.invoke(main, [str(a) for a in args], env=env, catch_exceptions=True)


def assert_refused(args, match: str, *, cwd=None, env=None) -> str:
    """Assert ``replay ARGS`` exits 2 with one line on stderr matching ``match`` (regex, case-insensitive).

    Returns that line. An uncaught exception (which a user would see as a traceback) fails.
    """
    res = invoke(args, cwd=cwd, env=env)
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        import traceback

        raise AssertionError("traceback instead of a refusal:\n" + "".join(
            traceback.format_exception(res.exception)))
    assert res.exit_code == 2, f"exit {res.exit_code}\nstdout: {res.stdout}\nstderr: {res.stderr}"
    lines = message_lines(res.stderr)
    assert len(lines) == 1, f"expected one line on stderr (besides load progress), got:\n{res.stderr}"
    assert "Traceback" not in res.stderr
    assert re.search(match, lines[0], re.IGNORECASE), f"{match!r} not in {lines[0]!r}"
    return lines[0]


def assert_ok(args, *, cwd=None, env=None):
    """Assert ``replay ARGS`` succeeds (exit 0, no exception); return the result."""
    res = invoke(args, cwd=cwd, env=env)
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        import traceback

        raise AssertionError("".join(traceback.format_exception(res.exception)))
    assert res.exit_code == 0, f"exit {res.exit_code}\nstdout: {res.stdout}\nstderr: {res.stderr}"
    return res
