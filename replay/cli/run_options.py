"""Click options made from the declared options of a run (:data:`replay.run.eval_options.EVAL_OPTIONS`).

``@run_option("runs", "-n")`` is ``--runs/-n`` with the declaration's default, its help text
(doc, what it accepts, unit) and its checking: the text is read as JSON (``1.5``, ``NaN``; a
bare word stays a string) and checked by the declaration, so ``replay eval --runs 0`` and
``replay.evaluate(runs=0)`` are refused with the same line.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from replay.run.eval_options import BY_NAME
from replay.util.errors import DataError
from replay.util.params import Param


class Existing(click.Path):
    """``click.Path(exists=True, ...)`` refused as the project refuses: one line naming the option and
    the path (``replay: error: --mapping FILE: no such file``, exit status 2), not click's usage text."""

    def __init__(self, *, file_okay: bool = True, dir_okay: bool = True):
        super().__init__(exists=False, file_okay=file_okay, dir_okay=dir_okay)

    def convert(self, value, param, ctx):
        opts = getattr(param, "opts", None) if getattr(param, "param_type_name", "") == "option" else None
        where = f"{opts[0]} {value}" if opts else str(value)
        p = Path(value).expanduser()
        if not p.exists():
            kind = "file" if not self.dir_okay else "directory" if not self.file_okay else "file or directory"
            raise DataError(where, f"no such {kind}")
        if p.is_dir() and not self.dir_okay:
            raise DataError(where, "is a directory, not a file")
        if not p.is_dir() and not self.file_okay:
            raise DataError(where, "is a file, not a directory")
        return super().convert(value, param, ctx)


DATA_DIR = click.option(
    "--data-dir",
    default=None,
    type=click.Path(),
    help="Look here first for dataset files (then $REPLAY_DATA_DIR, then the cache).",
)
MAPPING = click.option(
    "--mapping",
    default=None,
    type=Existing(dir_okay=False),
    help="Topic mapping (TOML) for a bag or MCAP file (docs/bags.md).",
)
ALLOW_MODULE = click.option(
    "--allow-module",
    "allow_modules",
    multiple=True,
    metavar="MODULE",
    help="Let the file this command reads name a filter, task or adapter as 'MODULE:Class' (importing MODULE "
    "runs its code); without it only built-in and installed (entry-point) ones are loaded. Repeatable.",
)


class Declared(click.ParamType):
    """A click type that reads the text as JSON and checks it with a :class:`Param`."""

    def __init__(self, param: Param):
        self.param = param
        self.name = param.type.__name__

    def convert(self, value, param, ctx):
        if not isinstance(value, str):  # a default, or given from Python
            return self.param.check(value)
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parsed = value
        if self.param.type is float and isinstance(parsed, (int, str)) and not isinstance(parsed, bool):
            try:
                parsed = float(parsed)  # an integer, or nan / inf (not JSON): refused as numbers
            except ValueError:
                pass
        elif self.param.type is str:
            parsed = value
        return self.param.check(parsed)


def help_text(p: Param, extra: str = "") -> str:
    """The ``--help`` line of a declared option: its doc, what it accepts and its unit."""
    unit = f" [{p.unit}]" if p.unit and p.unit not in p.doc.split() else ""
    return f"{p.doc[0].upper()}{p.doc[1:]}{unit}: {p.accepts()}.{extra}"


def run_option(name: str, *short: str, default=..., extra: str = ""):
    """The click option ``--<name>`` of the declared run option ``name`` (``default``: another one,
    e.g. ``replay tune``'s run count)."""
    p = BY_NAME[name]
    default = p.default if default is ... else default
    return click.option(
        f"--{name.replace('_', '-')}",
        *short,
        name,
        default=default,
        type=Declared(p),
        show_default=default is not None,
        metavar=p.type.__name__.upper(),
        help=help_text(p, extra),
    )


def quiet_notes(quiet: bool) -> None:
    """``-q``: the library's notes (logger ``replay``) down to warnings."""
    if quiet:
        import logging

        logging.getLogger("replay").setLevel(logging.WARNING)
