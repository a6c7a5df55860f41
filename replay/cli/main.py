"""The ``replay`` command line.

Bad input raises :class:`replay.util.errors.ReplayError`; :class:`Main` turns it into
one line on stderr and exit status 2 (no traceback).
"""

from __future__ import annotations

import sys

import click

from replay.cli.examples import add_examples
from replay.util.errors import ReplayError, bounded
from replay.util.version import __version__


class Main(click.Group):
    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except ReplayError as err:
            click.echo(f"replay: error: {bounded(err)}", err=True)
            ctx.exit(2)
        except MemoryError as err:  # not predicted (replay.run.resources): said as such, never "diverged"
            click.echo(f"replay: error: out of memory{f' ({err})' if str(err) else ''}", err=True)
            ctx.exit(2)
        finally:
            import gc

            gc.freeze()  # the exit's last collection skips what the command built (~0.2 s after a campaign)


@click.group(cls=Main)
@click.version_option(__version__, prog_name="replay")
def main():
    """Replay navigation logs through state-estimation filters and score them."""
    _notes_to_stderr()


def _notes_to_stderr() -> None:
    """One-line notices of the library (logger ``replay``: e.g. a one-time kernel compilation) on
    stderr, as ``replay: note: ...``; ``-q`` of a command raises the level to warnings."""
    import logging

    log = logging.getLogger("replay")
    if not any(getattr(h, "_replay_cli", False) for h in log.handlers):
        from replay.util.progress import NoteHandler  # a live progress bar is erased first

        h = NoteHandler(sys.stderr)
        h.setFormatter(logging.Formatter("replay: note: %(message)s"))
        h._replay_cli = True
        log.addHandler(h)
        log.propagate = False
    log.setLevel(logging.INFO)


def _register_optional():
    from replay.cli.datasets import datasets
    from replay.cli.listing import list_cmd

    main.add_command(datasets)
    main.add_command(list_cmd)
    from replay.cli.bags import export_cmd, inspect_cmd

    main.add_command(inspect_cmd)
    main.add_command(export_cmd)
    from replay.cli.evaluate import eval_cmd
    from replay.cli.reproduce import reproduce_cmd, rerun_cmd

    main.add_command(eval_cmd)
    from replay.cli.score import score_cmd

    main.add_command(rerun_cmd)
    main.add_command(reproduce_cmd)

    main.add_command(score_cmd)
    from replay.cli.convert import convert_cmd
    from replay.cli.res import res_cmd

    main.add_command(res_cmd)
    main.add_command(convert_cmd)
    from replay.cli.tune import tune_cmd

    main.add_command(tune_cmd)
    from replay.cli.campaign import COMMANDS as campaign_commands

    for cmd in campaign_commands:
        main.add_command(cmd)


_register_optional()
add_examples(main)

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
