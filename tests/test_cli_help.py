"""Every command's --help ends with 2-4 real examples whose options exist."""
import shlex

import click
import pytest
from click.testing import CliRunner

from replay.cli import main
from replay.cli.examples import EXAMPLES


def _commands(group, prefix=""):
    for name, cmd in group.commands.items():
        if isinstance(cmd, click.Group):
            yield from _commands(cmd, f"{prefix}{name} ")
        else:
            yield f"{prefix}{name}", cmd


@pytest.mark.parametrize("key,cmd", list(_commands(main)))
def test_help_ends_with_examples_that_parse(key, cmd):
    assert key in EXAMPLES and 2 <= len(EXAMPLES[key]) <= 4, key
    res = CliRunner().invoke(main, [*key.split(), "--help"])
    assert res.exit_code == 0 and res.output.rstrip().endswith(EXAMPLES[key][-1])
    names = {o for p in cmd.params for o in getattr(p, "opts", []) + getattr(p, "secondary_opts", [])}
    for example in EXAMPLES[key]:
        words = shlex.split(example)
        assert words[:1 + len(key.split())] == ["replay", *key.split()], example
        for w in words:
            if w.startswith("-") and not w.lstrip("-").replace(".", "").isdigit():
                assert w.split("=")[0] in names, f"{example}: {w} is not an option of replay {key}"
