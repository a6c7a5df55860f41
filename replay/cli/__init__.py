"""The ``replay`` command line: the only package that uses click.

``main`` is the entry point (``replay = "replay.cli:main"``); each command
group lives in its own module (``main``, ``datasets``, ``bags``, ``campaign``).
"""

from replay.cli.main import main

__all__ = ["main"]
