"""When a rule was declared (issue 36): git history decides "before" or "post hoc"; a post-hoc rule is capped
below "reproduced"; a baseline that loses its track cannot support a claim; an undecidable test is refused."""

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from replay.reproduce import render, spec
from replay.reproduce.rules import (
    EXPLORATORY,
    NOT,
    RECOVERED,
    RECOVERED_POST,
    REPRODUCED,
    Claim,
    Comparison,
    Rule,
    decide,
)

ROOT = Path(__file__).resolve().parents[1]
PAPERS = ("000", "001", "002", "003")


def git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=True).stdout


def history_or_skip() -> None:
    """Skip (with the reason) where git history cannot decide: no git, not a checkout, or a shallow clone."""
    if shutil.which("git") is None:
        pytest.skip("git is not installed: the history that decides 'declared' is unavailable")
    try:
        shallow = git("rev-parse", "--is-shallow-repository").strip()
    except subprocess.CalledProcessError:
        pytest.skip("not a git checkout: the history that decides 'declared' is unavailable")
    if shallow != "false":
        pytest.skip("a shallow clone: the first commits of rules and documents are not in its history")


def rule_commit(paper: str, cid: str) -> str | None:
    """The commit that wrote claim ``cid``'s rule line as it reads now (None: not committed yet)."""
    rel = f"replay/papers/{paper}.toml"
    lines = (ROOT / rel).read_text(encoding="utf-8").splitlines()
    start = lines.index(f'id = "{cid}"')
    n = next(i for i in range(start, len(lines)) if lines[i].startswith("rule = ")) + 1
    sha = git("blame", "--porcelain", "-L", f"{n},{n}", "--", rel).split()[0]
    return None if set(sha) == {"0"} else sha


def evidence_commit(paper: str) -> str | None:
    """The first commit of the paper's document (the first run of its evidence anyone saw; None: never committed)."""
    shas = git("log", "--follow", "--format=%H", "--", f"docs/reproduction/{paper}.md").split()
    return shas[-1] if shas else None


def before_by_git(rule: str | None, evidence: str | None) -> bool:
    """The rule was committed strictly before the evidence's first commit (an ancestor of it, not it)."""
    if evidence is None:
        return rule is not None
    if rule is None or rule == evidence:
        return False
    ancestor = subprocess.run(["git", "-C", str(ROOT), "merge-base", "--is-ancestor", rule, evidence])
    return ancestor.returncode == 0


@pytest.mark.parametrize("paper", PAPERS)
def test_each_rules_declared_is_what_git_history_says(paper):
    history_or_skip()
    ev = evidence_commit(paper)
    for c in spec.claims(spec.load(paper), f"{paper}.toml"):
        truth = "before" if before_by_git(rule_commit(paper, c.id), ev) else "post hoc"
        assert c.rule.declared == truth, f"{paper}.toml claim {c.id!r}: declared {c.rule.declared!r}, git: {truth!r}"


def test_before_by_git_orders_commits():
    history_or_skip()
    first, second = git("rev-list", "--max-parents=0", "HEAD").split()[0], git("rev-parse", "HEAD").strip()
    assert before_by_git(first, second) and not before_by_git(second, first)
    assert not before_by_git(second, second) and not before_by_git(None, second)
    assert before_by_git(first, None)


def test_a_missing_declared_is_refused_naming_the_claim():
    raw = {"claim": [{"id": "c", "words": "w", "paper": "p", "evidence": "#e", "rule": {"decides": "x", "cells": "c",
                                                                                        "statistic": "s"}}]}
    with pytest.raises(ValueError, match=r"^x\.toml: claim 'c': missing \['rule\.declared'\]$"):
        spec.claims(raw, "x.toml")
    with pytest.raises(ValueError, match="rule declared 'later'"):
        Rule("x", "c", "s", declared="later")


def better(n=10, shift=-1.0, lost_b=None):
    rng = np.random.default_rng(1)
    b = rng.normal(5.0, 0.1, n)
    lost = np.zeros(n, bool) if lost_b is None else lost_b
    return Comparison("A < B", b + shift + rng.normal(0, 0.05, n), b, np.zeros(n, bool), lost)


def claim(rule, cid="c"):
    return Claim(cid, "A < B", "A < B", rule, "#e-c")


def test_a_post_hoc_rule_is_capped_below_reproduced():
    ev = {"p": [better()], "q": [better()], "bad": [better(shift=+1.0)]}
    before, post = (Rule("p", "paper", "A - B", test="t", declared=d) for d in ("before", "post hoc"))
    assert decide([claim(before)], ev)[0].label == REPRODUCED
    v, = decide([claim(post)], ev)
    assert v.label == EXPLORATORY and v.deciding[0].holds and v.deciding[0].p_adj < 1e-6
    cond = dict(test="t", condition="q", condition_text="Q small")
    assert decide([claim(Rule("bad", "paper", "A - B", declared="before", **cond))], ev)[0].label == RECOVERED
    v, = decide([claim(Rule("bad", "paper", "A - B", declared="post hoc", **cond))], ev)
    assert v.label == RECOVERED_POST and "A < B: mean 0.99" in v.gap  # the paper-setting result beside it
    row = render.verdict_table([v]).splitlines()[2]
    assert "post hoc: after runs of its evidence were seen" in row and "stated post-hoc condition: Q small" in row


def test_a_baseline_that_loses_its_track_cannot_support_the_claim():
    lost = np.zeros(10, bool)
    lost[:2] = True  # 20 % of the baseline's runs lost: above the default 10 %
    ev = {"p": [better(lost_b=lost)], "w": [better(shift=+0.5)]}
    v, = decide([claim(Rule("p", "paper", "A - B", test="t", declared="before", working="w"))], ev)
    assert v.deciding[0].holds and v.label == NOT and v.broken == v.deciding
    assert v.working[0].estimate == pytest.approx(0.5, abs=0.05) and not v.working[0].holds
    cell = render.found(v)
    assert "losing more than 10 % of runs" in cell and "A < B: b lost 2/10" in cell
    assert "Working baselines: A < B: mean 0.493 [0.476, 0.509], p_adj = 1" in cell
    v, = decide([claim(Rule("p", "paper", "A - B", test="t", declared="before", max_lost=0.2))], ev)
    assert v.label == REPRODUCED and v.broken == []  # 2 of 10 is not more than a declared 20 %
    ev = {"p": [better(lost_b=np.ones(10, bool))]}  # an ablation's lost runs are evidence: max_lost = 1 keeps them
    v, = decide([claim(Rule("p", "paper", "A - B", test="t", declared="before", max_lost=1.0))], ev)
    assert v.label == REPRODUCED and v.broken == []
    with pytest.raises(ValueError, match=r"max_lost 1.5: a share of runs in \[0, 1\]"):
        Rule("p", "paper", "A - B", max_lost=1.5)


@pytest.mark.parametrize(
    "comparison, test, why",
    [
        (Comparison("b1hz: a < b", [1.0, 2.0], [1.5, 2.5]), "interval", "an interval test without a target"),
        (Comparison("t5: a", [1.0, 2.0], target=1.5), "t", "a paired test (t) without a pair"),
        (Comparison("t5: a", [1.0, 2.0], target=1.5), "auto", "a paired test (auto) without a pair"),
        (Comparison("t5: lost", (), ()), "mcnemar", "an exact McNemar test without the lost flags"),
        (Comparison("t5: lost"), "fisher", "a Fisher test without lost counts"),
    ],
)
def test_an_undecidable_test_is_refused_in_one_line_naming_the_claim(comparison, test, why):
    with pytest.raises(ValueError) as e:
        decide([claim(Rule("x", "c", "s", test=test), "bohai-move")], {"x": [comparison]})
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("claim 'bohai-move': 'x' comparison") and why in msg
    own = Comparison(comparison.name, comparison.a, comparison.b, target=comparison.target, test=test)
    with pytest.raises(ValueError, match=re.escape(why)):  # a comparison's own test is checked the same way
        decide([claim(Rule("x", "c", "s"), "bohai-move")], {"x": [own]})


def test_papers_rules_all_declare_when():
    for paper in PAPERS:
        for c in spec.claims(spec.load(paper), f"{paper}.toml"):
            assert c.rule.declared in ("before", "post hoc")
