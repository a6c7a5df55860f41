"""What the CLI tests assert of a command: a refusal is one line ``replay: error: ...`` and exit 2."""
from __future__ import annotations

from click.testing import CliRunner

from replay.cli.main import main


def refused(args, message):
    """Run ``replay ARGS``; assert exit 2 and one error line containing MESSAGE; return the line."""
    r = CliRunner().invoke(main, list(map(str, args)))
    lines = r.output.strip().splitlines()
    assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("replay: error:"), r.output
    assert message in lines[0], r.output
    return lines[0]


def ok(args):
    """Run ``replay ARGS``; assert exit 0; return the output."""
    r = CliRunner().invoke(main, list(map(str, args)))
    assert r.exit_code == 0, r.output
    return r.output
