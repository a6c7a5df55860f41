"""A paper's reproduction as data: ``replay/papers/NNN.toml`` beside its prose ``replay/papers/NNN.md``.

The TOML file holds what a referee reads before the run: the experiments (datasets, filters and
their parameters, the paper's numbers), the baselines' tuning grids and the claims, each with its
deciding rule (:class:`replay.reproduce.rules.Rule`), the label of the previous document and the
anchor of its evidence row::

    [[claim]]
    id = "depth"
    words = "depth RMSE: GPF < MMPF < EKF (Fig. 4)"
    paper = "GPF < MMPF < EKF (figures only)"
    evidence = "#e-order"
    old = "deviation explained (holds in 1/12 cells)"
    rule = { declared = "before", decides = "depth@paper", cells = "the paper's setting", statistic = "depth RMSE" }

``declared`` (required): ``"before"`` only for a rule committed before any run of its evidence was seen
(git history decides: ``tests/test_reproduce_declared.py``), else ``"post hoc"``.

Every key is checked: an unknown one is refused naming the file and the claim, so a misspelt rule
field cannot silently fall back to its default. The experiments' tables are read by the paper's
module (``replay/reproduce/pNNN.py``), which declares the keys of each kind of entry and checks
every entry with :func:`check` before any run.
"""

from __future__ import annotations

import tomllib
from dataclasses import fields
from pathlib import Path

from .rules import Claim, Rule

PAPERS = Path(__file__).resolve().parents[1] / "papers"
CLAIM_KEYS = {"id", "words", "paper", "evidence", "old", "rule"}
RULE_KEYS = {f.name for f in fields(Rule)}


def path(paper: str, suffix: str) -> Path:
    """``replay/papers/<paper>.<suffix>``."""
    return PAPERS / f"{paper}.{suffix}"


def check(entry: dict, keys: str, where: str) -> dict:
    """``entry`` if it has every key of ``keys`` (space-separated; ``key?``: optional) and no other, else a
    ``ValueError`` naming ``where`` (the file and the entry: ``"003.toml: setting 'N = 50'"``)."""
    names = keys.split()
    unknown = set(entry) - {k.rstrip("?") for k in names}
    missing = {k for k in names if not k.endswith("?")} - set(entry)
    if unknown or missing:
        what = [f"{w} key(s) {sorted(v)}" for w, v in (("unknown", unknown), ("missing", missing)) if v]
        raise ValueError(f"{where}: {', '.join(what)}")
    return entry


def load(paper: str) -> dict:
    """The paper's TOML table (``ValueError`` naming the file on a syntax error)."""
    p = path(paper, "toml")
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{p.name}: {e}") from None


def claims(spec: dict, where: str = "paper") -> list[Claim]:
    """The ``[[claim]]`` tables as :class:`Claim` objects, every key checked (module docstring)."""
    out = []
    for i, c in enumerate(spec.get("claim", []), 1):
        name = f"{where}: claim {c.get('id', i)!r}"
        bad = set(c) - CLAIM_KEYS or set(c.get("rule", {})) - RULE_KEYS
        if bad:
            raise ValueError(f"{name}: unknown key(s) {sorted(bad)}")
        missing = CLAIM_KEYS - {"old"} - set(c) | {"rule.declared"} - {f"rule.{k}" for k in c.get("rule", {})}
        if missing:
            raise ValueError(f"{name}: missing {sorted(missing)}")
        out.append(Claim(c["id"], c["words"], c["paper"], Rule(**c["rule"]), c["evidence"]))
    return out


def old_labels(spec: dict) -> dict[str, str]:
    """Claim id -> the label of the previous document ("(new row)" when it had none)."""
    return {c["id"]: c.get("old", "(new row)") for c in spec.get("claim", [])}
