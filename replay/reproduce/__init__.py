"""Paper reproductions: ``replay reproduce PAPER``.

``REPRODUCTIONS`` maps a paper number (the prefix of its file in the seeds) to
"module:function"; the function is called as
``function(runs=..., seed=..., data_dir=..., doc=..., quick=...)``, prints the
paper's numbers beside ours (with 95 % intervals) and writes the Markdown
report (``docs/reproduction/<paper>.md`` by default).
"""

from importlib import import_module

from replay.util.data_dirs import check_data_dir
from replay.util.errors import ReplayError

REPRODUCTIONS: dict[str, str] = {
    "000": "replay.reproduce.p000:run",
    "002": "replay.reproduce.p002:run",
    "001": "replay.reproduce.p001:run",
    "003": "replay.reproduce.p003:run",
}


def run_reproduction(paper: str, **options):
    key = paper.zfill(3)
    try:
        module, func = REPRODUCTIONS[key].split(":")
    except KeyError:
        known = ", ".join(sorted(REPRODUCTIONS)) or "none yet"
        raise ReplayError(f"no reproduction for paper {paper!r} (known: {known})") from None
    check_data_dir(options.get("data_dir"), "data_dir")  # a mistyped one: 002 would leave out its Bohai rows
    return getattr(import_module(module), func)(**options)
