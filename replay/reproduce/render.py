"""The one renderer of reproduction documents: a prose template, the verdict table, tables as data.

A paper's document is ``replay/papers/NNN.md``, Markdown with ``${name}``
placeholders (:class:`string.Template`; ``$$`` for a literal dollar), filled by
:func:`render` from ``fields`` (text the paper's code computes: numbers, tables made with
:func:`table`) and the verdicts (:func:`replay.reproduce.rules.decide`). Every placeholder
must be given and every field used, so a template and its code cannot drift apart silently.
The template must hold ``${verdicts}`` (the verdict table, :func:`verdict_table`) before its
first ``## `` section other than ``## Verdict``: each document opens with its verdicts.

The verdict table has one row per claim: the claim (the paper's words), the paper's number,
the label, the rule, when it was declared (before any run of its evidence, or post hoc), the
test, the Holm-adjusted p-values or intervals of the deciding comparisons (with the stated
condition's or the ablation's when they decided, the residual gap beside a *recovered* row, a
baseline that lost too many runs to support the claim and the working baselines' results), and
a link to the evidence row.
An evidence row carries the anchor :func:`anchor_tag` of its claim's ``evidence``; :func:`fmt`
and :func:`pm` print a mean ± half-width and a paired difference in the tables.
"""

from __future__ import annotations

import re
from pathlib import Path
from string import Template

import numpy as np

from replay.scoring.significance import pairs, t_interval

from .rules import DECLARED, MECHANISM, RECOVERED, RECOVERED_POST, Verdict, counts
from .spec import PAPERS
from .tables import cell

TEMPLATES = PAPERS


def table(head: list[str], rows: list[list]) -> str:
    """A Markdown table (cells escaped: ``|`` and newlines)."""
    lines = ["| " + " | ".join(cell(h) for h in head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(cell(x) for x in r) + " |" for r in rows]
    return "\n".join(lines)


def fmt(m: float, c: float | None = None) -> str:
    """``m ± c`` with two significant digits on the half-width, signed (``m`` to 3 digits without one)."""
    if not np.isfinite(m):
        return "n/a"
    if c is None or not np.isfinite(c) or c <= 0:
        return f"{m:.3g}"
    d = max(0, 1 - int(np.floor(np.log10(c))))
    return f"{m:+.{d}f} ± {c:.{d}f}"


def pm(a, b) -> str:
    """Paired a − b over runs as a table prints it: mean ± 95 % t half-width (:func:`fmt`)."""
    return fmt(*t_interval(np.subtract(*pairs(a, b))))


def anchor_tag(evidence: str) -> str:
    """The HTML anchor an evidence row carries for the link ``evidence`` (``#e-depth`` -> ``<a id="e-depth"></a>``)."""
    name = evidence.lstrip("#")
    if not re.fullmatch(r"[\w\-]+", name):
        raise ValueError(f"evidence anchor {evidence!r}: letters, digits, '-' and '_' only")
    return f'<a id="{name}"></a>'


def found(v: Verdict) -> str:
    """The verdict table's evidence cell of ``v``: the deciding outcomes, and the condition's or ablation's."""
    out = "; ".join(o.text() for o in v.deciding)
    if v.label in (RECOVERED, RECOVERED_POST):
        out = (
            "under the condition: " + "; ".join(o.text() for o in v.support) + f". Residual gap in the paper's "
            f"setting: {v.gap}"
        )
    elif v.label == MECHANISM:
        out += ". Ablation: " + "; ".join(o.text() for o in v.support)
    for kind, words in (("condition", "Stated condition, not met"), ("mechanism", "Ablation, not shown")):
        if v.tried.get(kind):
            out += f". {words}: " + "; ".join(o.text() for o in v.tried[kind])
    return out + baselines(v)


def baselines(v: Verdict) -> str:
    """The deciding comparisons whose baseline lost too many runs to support the claim, and the working baselines."""
    share = lambda o: f"{int(sum(o.comparison.lost_b))}/{len(o.comparison.lost_b)}"
    out = ""
    if v.broken:
        out += f". Baseline(s) losing more than {100 * v.claim.rule.max_lost:g} % of runs (not at their best: cannot "
        out += "support the claim): " + "; ".join(f"{o.comparison.name}: b lost {share(o)}" for o in v.broken)
    if v.working:
        out += ". Working baselines: " + "; ".join(o.text() for o in v.working)
    return out


def verdict_table(verdicts: list[Verdict]) -> str:
    """The verdict table (module docstring) and the count of each label."""
    rows = [
        [
            v.claim.words,
            v.claim.paper,
            f"**{v.label}**",
            v.rule,
            DECLARED[v.claim.rule.declared],
            v.tests,
            found(v),
            f"[{v.claim.evidence.lstrip('#')}]({v.claim.evidence})",
        ]
        for v in verdicts
    ]
    head = [
        "claim",
        "paper",
        "verdict",
        "rule",
        "when declared",
        "test",
        "adjusted p / interval (deciding comparisons)",
        "evidence",
    ]
    return table(head, rows) + "\n\n" + counts(verdicts)


def render(template: str | Path, fields: dict, verdicts: list[Verdict]) -> str:
    """The document: ``template`` (a path, or a paper number "NNN" for ``replay/papers/NNN.md``) with
    ``${verdicts}`` and every ``fields`` placeholder filled (module docstring)."""
    path = TEMPLATES / f"{template}.md" if re.fullmatch(r"\d{3}", str(template)) else Path(template)
    text = path.read_text(encoding="utf-8")
    t = Template(text)
    names = {m.group("named") or m.group("braced") for m in t.pattern.finditer(text)} - {None}
    if "verdicts" not in names:
        raise ValueError(f"{path.name}: no ${{verdicts}} placeholder (a document opens with its verdicts)")
    before = text[: text.index("${verdicts}")]
    early = [h for h in re.findall(r"^## .*$", before, flags=re.M) if h.strip() != "## Verdict"]
    if early:
        raise ValueError(f"{path.name}: section {early[0]!r} before the verdict table")
    missing, unused = names - set(fields) - {"verdicts"}, set(fields) - names
    if missing or unused:
        raise ValueError(
            f"{path.name}: placeholders without a value {sorted(missing)}, values without a "
            f"placeholder {sorted(unused)}"
        )
    return t.substitute({k: str(v) for k, v in fields.items()}, verdicts=verdict_table(verdicts))
