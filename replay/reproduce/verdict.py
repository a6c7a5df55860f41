"""What every reproduction document shares: the Monte Carlo rows, the footer, portable writing.

The verdict vocabulary, the rules and the decision are :mod:`replay.reproduce.rules`; the one
renderer is :mod:`replay.reproduce.render`. :class:`Claim`, :data:`VERDICTS` and
:func:`verdict_table` below are the old three-label vocabulary ("deviation explained"), kept
only until every paper has moved to :mod:`replay.reproduce.rules`; new code must not use them.

A reproduction document (``docs/reproduction/NNN.md``) opens with a **verdict
table**: one row per claim of the paper, with our number and its 95 %
interval, the paper's number, and one verdict of :data:`VERDICTS`, linking to
the section that holds the evidence. The rows of every table come from
:func:`replay.run.evaluation.evaluate` (the pipeline of ``replay eval``) through
:func:`result_rows`, so a document shows the same columns as a leaderboard:
mean ± 95 % half-width, median, ``lost k/N`` and ``diverged``.

:func:`write_document` refuses text that holds a machine-specific path (a
home, a temporary directory, the checkout's location) and writes the file
atomically; :func:`footer` states the command and the total runtime.
"""

from __future__ import annotations

import os
import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from replay.scoring.summary import lost_cell
from replay.util.files import write_atomic

VERDICTS = ("reproduced", "deviation explained", "not reproduced")


@dataclass
class Claim:
    """One claim of a paper and what we found.

    ``verdict``: ``reproduced`` (our interval holds the paper's number, or the claimed ordering
    holds with a paired interval excluding 0), ``deviation explained`` (it does not, and
    ``cause`` names a cause demonstrated by a row of the document), ``not reproduced``.
    ``evidence``: the anchor of the section or table row holding the numbers (``#table-5``).
    """

    claim: str
    ours: str
    paper: str
    verdict: str
    evidence: str
    cause: str = ""

    def __post_init__(self):
        if self.verdict not in VERDICTS:
            raise ValueError(f"verdict {self.verdict!r}: one of {', '.join(VERDICTS)}")
        if self.verdict == "deviation explained" and not self.cause:
            raise ValueError(f"claim {self.claim!r}: a deviation is explained only with its cause")


def cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def verdict_table(claims: list[Claim]) -> str:
    """The Markdown verdict table (claim, ours, paper, verdict, evidence)."""
    lines = ["| claim | ours (95 % interval) | paper | verdict | evidence |", "|---|---|---|---|---|"]
    for c in claims:
        verdict = f"**{c.verdict}**" + (f": {cell(c.cause)}" if c.cause else "")
        lines.append(
            f"| {cell(c.claim)} | {cell(c.ours)} | {cell(c.paper)} | {verdict} | "
            f"[{c.evidence.lstrip('#')}]({c.evidence}) |"
        )
    counts = {v: sum(c.verdict == v for c in claims) for v in VERDICTS}
    lines.append("")
    lines.append(", ".join(f"{n} {v}" for v, n in counts.items()) + f" (of {len(claims)} claims).")
    return "\n".join(lines)


def anchor(title: str) -> str:
    """The GitHub-style anchor of a Markdown heading."""
    a = re.sub(r"[^\w\- ]", "", title.strip().lower())
    return "#" + a.replace(" ", "-")


def mean_ci(row: dict, key: str = "pos_rmse", digits: int = 3) -> str:
    """``mean ± half-width`` of a leaderboard row's metric (``n/a`` when not finite)."""
    v, c = row.get(key, np.nan), row.get(f"{key}_ci95", np.nan)
    try:
        v, c = float(v), float(c)
    except (TypeError, ValueError):
        return "n/a"
    if not np.isfinite(v):
        return "n/a"
    return f"{v:.{digits}f}" + (f" ± {c:.{digits}f}" if np.isfinite(c) else "")


def result_rows(rows: list[dict], metrics=("pos_rmse",), names=None, digits: int = 3) -> str:
    """A Markdown table of leaderboard rows (:mod:`replay.scoring.summary`): label (or ``names``), each
    metric as mean ± 95 %, the median position RMSE, ``lost k/N`` and ``diverged k/N``."""
    head = ["filter"] + [m for m in metrics] + ["median pos_rmse", "lost", "diverged"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for i, r in enumerate(rows):
        name = names[i] if names else (r.get("label") or r.get("filter"))
        med = r.get("pos_rmse_median", np.nan)
        cells = [cell(name)] + [mean_ci(r, m, digits) for m in metrics]
        cells += [
            f"{float(med):.{digits}f}" if np.isfinite(float(med)) else "n/a",
            lost_cell(r),
            f"{r.get('diverged', 0)}/{r.get('runs', 0)}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def footer(command: str, seconds: float) -> str:
    """The closing lines: the command that wrote the document and its total runtime."""
    mins = seconds / 60
    took = f"{seconds:.0f} s" if seconds < 120 else f"{mins:.1f} min"
    return (
        f"\n---\nGenerated by `{command}` in {took} (2-core machine, total wall time). "
        "Every number comes from `replay.run.evaluation.evaluate`, the pipeline of `replay eval`.\n"
    )


def _machine_paths() -> list[str]:
    out = {str(Path.home()), tempfile.gettempdir(), str(Path.cwd()), str(Path(__file__).resolve().parents[2])}
    out |= {os.environ.get(k, "") for k in ("TMPDIR", "HOME", "REPLAY_CACHE_DIR")}
    return sorted((p for p in out if p and p not in ("/", ".")), key=len, reverse=True)


def check_portable(text: str, where: str) -> None:
    """Refuse text holding a machine-specific path (a home, a temp dir, the checkout's location)."""
    for p in _machine_paths():
        if p in text:
            raise ValueError(
                f"{where}: holds the machine-specific path {p!r}; write it relative to the repository or as a command"
            )


def write_document(path, text: str) -> Path:
    """Check ``text`` is portable and write it to ``path`` atomically."""
    path = Path(path)
    check_portable(text, str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, text)
    return path


class Stopwatch:
    """Total wall time of a reproduction, for :func:`footer`."""

    def __init__(self):
        self.t0 = time.perf_counter()

    @property
    def seconds(self) -> float:
        return time.perf_counter() - self.t0
