"""Verdicts a referee signs: the labels, rules declared beside each claim, one decision.

The vocabulary (:data:`LABELS`):

* :data:`REPRODUCED` — the paper's number or ordering holds within our interval **in the paper's own
  setting** (the rule's ``decides`` comparisons), by a rule declared before any run of its evidence;
* :data:`RECOVERED` — it does not there, but holds under a condition named in the rule before the run
  (``condition``, ``condition_text``); the residual gap in the paper's setting is printed beside it;
* :data:`EXPLORATORY` and :data:`RECOVERED_POST` — the same two outcomes under a rule written after
  runs of its evidence had been seen (``declared = "post hoc"``): such a rule can give no more;
* :data:`MECHANISM` — not reproduced, and an ablation named in the rule (``mechanism``,
  ``mechanism_text``) shows why;
* :data:`NOT` — not reproduced.

A paper declares its claims as data (:class:`Claim`, each with its :class:`Rule`: which
comparisons decide, in which cells, with which statistic and test, at which alpha), computes
its evidence (a mapping ``key -> [Comparison, ...]`` filled from the runs) and calls
:func:`decide`, which tests every comparison, Holm-adjusts each family (:func:`replay.scoring
.significance.holm`; by default a claim's family is every comparison it draws on: deciding,
condition and mechanism), and applies the rules in the order above. Nothing is chosen after
seeing the data: a condition or an ablation that the rule does not name cannot rescue a claim,
and a claim that holds in 1 of 12 cells holds only if its rule asks for one cell and that cell
survives the Holm adjustment over the 12. Each rule records when it was declared (``declared``:
``"before"`` any run of its evidence was seen, else ``"post hoc"``; git history decides, checked by
``tests/test_reproduce_declared.py``). A comparison against a baseline that lost more than
``max_lost`` of its runs (``lost_b``) cannot support a positive label (a baseline not at its best);
``working`` names comparisons against working baselines, printed beside the verdict. A comparison
its test cannot decide (an interval without a target, a paired test without a pair) is refused.

Tests (:data:`TESTS`; every p-value one-sided, "a < b": list the arm claimed smaller as ``a``):

* ``auto`` — ``wilcoxon`` when either arm lost a run (per-run errors bimodal:
  :func:`replay.scoring.significance.bimodal`), else ``t``;
* ``t`` — paired t-test; the interval is the mean difference ± the 95 % Student-t half-width;
* ``wilcoxon`` — Wilcoxon signed-rank; the interval is the median difference's bootstrap interval;
* ``mcnemar`` — exact McNemar test on paired lost flags (``lost_a`` fewer than ``lost_b``);
* ``fisher`` — Fisher's exact test on ``counts = (k_a, n_a, k_b, n_b)`` lost runs (unpaired);
* ``interval`` — the paper's number ``target`` lies in our 95 % interval of ``a`` (mean ± t
  half-width, or the median's bootstrap interval when ``lost_a`` has a lost run); no p-value,
  not in a Holm family.

Rendering: :mod:`replay.reproduce.render` (the verdict table, templates).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from replay.scoring import significance as sig

REPRODUCED = "reproduced"
RECOVERED = "recovered under a stated condition"
EXPLORATORY = "exploratory"
RECOVERED_POST = "recovered under a stated post-hoc condition"
MECHANISM = "not reproduced — mechanism shown"
NOT = "not reproduced"
LABELS = (REPRODUCED, RECOVERED, EXPLORATORY, RECOVERED_POST, MECHANISM, NOT)
CAPPED = {REPRODUCED: EXPLORATORY, RECOVERED: RECOVERED_POST}  # the most a post-hoc rule can give
DECLARED = {"before": "before any run of its evidence", "post hoc": "post hoc: after runs of its evidence were seen"}
PAIRED = ("auto", "t", "wilcoxon")
TESTS = ("auto", "t", "wilcoxon", "mcnemar", "fisher", "interval")
TEST_NAMES = {
    "t": "paired t",
    "wilcoxon": "Wilcoxon signed-rank",
    "mcnemar": "exact McNemar",
    "fisher": "Fisher exact",
    "interval": "95 % interval holds the paper's number",
}


@dataclass(frozen=True)
class Rule:
    """How a claim is decided; declared in code beside the claim, before any run.

    ``decides``: the evidence key of the comparisons in the paper's own setting; ``cells``: those
    cells in words; ``statistic``: what is compared, in words; ``test``: one of :data:`TESTS`;
    ``alpha``: the family-wise level; ``need``: how many deciding comparisons must hold (None:
    every one; ``"majority"``: more than half); ``condition``/``condition_text``: the evidence
    key and the words of the stated condition of :data:`RECOVERED`; ``mechanism`` and
    ``mechanism_text``: those of the ablation of :data:`MECHANISM`; ``family``: a Holm family
    shared with other claims ("" = the claim's own); ``declared``: "before" or "post hoc" (module docstring);
    ``max_lost``: the share of lost runs above which a baseline (``lost_b``) cannot support a positive
    label (1: arm b is an ablation of the filter, not a baseline, and its lost runs are evidence); ``working``:
    the evidence key of comparisons against working baselines, printed beside."""

    decides: str
    cells: str
    statistic: str
    test: str = "auto"
    alpha: float = 0.05
    need: int | str | None = None
    condition: str = ""
    condition_text: str = ""
    mechanism: str = ""
    mechanism_text: str = ""
    family: str = ""
    declared: str = "post hoc"
    max_lost: float = 0.1
    working: str = ""

    def __post_init__(self):
        if self.declared not in DECLARED:
            raise ValueError(f"rule declared {self.declared!r}: one of {', '.join(map(repr, DECLARED))}")
        if not 0 <= self.max_lost <= 1:
            raise ValueError(f"rule max_lost {self.max_lost}: a share of runs in [0, 1]")
        if self.test not in TESTS:
            raise ValueError(f"rule test {self.test!r}: one of {', '.join(TESTS)}")
        if not 0 < self.alpha < 1:
            raise ValueError(f"rule alpha {self.alpha}: between 0 and 1")
        if self.need is not None and self.need != "majority" and not (isinstance(self.need, int) and self.need >= 1):
            raise ValueError(f"rule need {self.need!r}: at least 1 comparison, 'majority' or None (every one)")
        for key, words, what in (
            (self.condition, self.condition_text, "condition"),
            (self.mechanism, self.mechanism_text, "mechanism"),
        ):
            if bool(key) != bool(words):
                raise ValueError(f"rule {what}: its evidence key and its words are declared together")

    def text(self) -> str:
        """The rule in words, as the document prints it beside the verdict."""
        need = {None: "every comparison", "majority": "more than half of the comparisons"}.get(
            self.need, f"at least {self.need} comparison(s)"
        )
        how = (
            f"{need} inside the interval"
            if self.test == "interval"
            else f"{need} significant at α = {self.alpha:g} (one-sided, Holm-adjusted over the family)"
        )
        out = f"{self.statistic}; cells: {self.cells}; {how}"
        if self.condition_text:
            out += f"; stated {'' if self.declared == 'before' else 'post-hoc '}condition: {self.condition_text}"
        if self.mechanism_text:
            out += f"; ablation: {self.mechanism_text}"
        return out


@dataclass(frozen=True)
class Claim:
    """One claim of a paper: ``id`` (short, unique), ``words`` (the paper's claim), ``paper`` (the
    paper's number or ordering), ``rule``, ``evidence`` (the anchor of its evidence row, ``#e-…``)."""

    id: str
    words: str
    paper: str
    rule: Rule
    evidence: str


@dataclass
class Comparison:
    """One comparison of the evidence: ``a`` the per-run values of the arm claimed smaller, ``b``
    the paired values of the other (same runs, NaN pairs left out); ``lost_a``/``lost_b`` their
    lost flags (they choose the rank test; ``mcnemar`` tests them); ``counts`` = (k_a, n_a, k_b,
    n_b) for ``fisher``; ``target``: the paper's number for ``interval``; ``name``: the cell in words."""

    name: str
    a: object = ()
    b: object = ()
    lost_a: object = None
    lost_b: object = None
    counts: tuple | None = None
    target: float | None = None
    test: str = ""  # this comparison's own test (one of TESTS), declared with it; "": the rule's


@dataclass
class Outcome:
    """A tested comparison: the test used, the estimate and its interval, raw and adjusted p."""

    comparison: Comparison
    test: str
    estimate: float
    lo: float
    hi: float
    p: float = float("nan")
    p_adj: float = float("nan")
    holds: bool = False

    def text(self, digits: int = 3) -> str:
        g = lambda v: f"{v:.{digits}g}" if v is not None and np.isfinite(v) else "n/a"
        c = self.comparison
        if self.test == "mcnemar":
            a, b = np.asarray(c.lost_a, bool), np.asarray(c.lost_b, bool)
            body = f"{c.name}: lost {int(a.sum())} vs {int(b.sum())} of {len(a)} (paired)"
        elif self.test == "fisher":
            body = f"{c.name}: lost {c.counts[0]}/{c.counts[1]} vs {c.counts[2]}/{c.counts[3]}"
        else:
            lost = self.test == "interval" and c.lost_a is not None and sig.bimodal(c.lost_a, [])
            what = "median" if self.test == "wilcoxon" or lost else "mean"  # test_one's estimate
            body = f"{c.name}: {what} {g(self.estimate)} [{g(self.lo)}, {g(self.hi)}]"
        if self.test == "interval":
            return f"{body} vs paper {g(self.comparison.target)}"
        p = p_text(self.p_adj)
        return f"{body}, p_adj {p if p.startswith('<') else '= ' + p}"


@dataclass
class Verdict:
    """A decided claim: its label, the rule text, the tests used, the deciding outcomes (and those
    of the condition or ablation that decided), the residual gap of a :data:`RECOVERED` row, and
    ``tried``: the outcomes of a declared condition or ablation that was tested and did not hold
    (``{"condition": [...], "mechanism": [...]}``), printed so that a reader sees it was tried."""

    claim: Claim
    label: str
    rule: str
    tests: str
    deciding: list = field(default_factory=list)
    support: list = field(default_factory=list)
    gap: str = ""
    tried: dict = field(default_factory=dict)
    broken: list = field(default_factory=list)  # deciding outcomes against a baseline that lost too many runs
    working: list = field(default_factory=list)  # outcomes against working baselines (the rule's ``working``)


def per_run(result, metric: str = "pos_rmse") -> tuple[np.ndarray, np.ndarray]:
    """Per-run values of ``metric`` of one filter's result (``Evaluation.results[i]``, whose ``runs``
    are per-run metric dicts) and its lost flags. A diverged run is +inf and lost: the worst error,
    kept by the rank tests (a t-test over it has no p-value, so the comparison does not hold)."""
    div = np.array([bool(m.get("diverged")) for m in result.runs])
    val = np.array([m.get(metric, np.nan) for m in result.runs], float)
    lost = np.array([bool(m.get("lost")) for m in result.runs]) | div
    return np.where(div, np.inf, val), lost


def paired_runs(name: str, result_a, result_b, metric: str = "pos_rmse") -> Comparison:
    """The comparison "``result_a`` has the smaller ``metric``" over the same runs (:func:`per_run`)."""
    a, lost_a = per_run(result_a, metric)
    b, lost_b = per_run(result_b, metric)
    return Comparison(name, a, b, lost_a, lost_b)


def p_text(p: float) -> str:
    if not np.isfinite(p):
        return "n/a"
    return f"{p:.2g}" if p >= 0.001 else "< 0.001"


def _choose(test: str, c: Comparison) -> str:
    if test != "auto":
        return test
    return sig.choose_test(c.lost_a, c.lost_b)


def test_one(c: Comparison, test: str, rng: np.random.Generator) -> Outcome:
    """The raw outcome of one comparison (p one-sided: a < b)."""
    kind = _choose(test, c)
    nan = float("nan")
    if kind == "interval":
        a = np.asarray(c.a, float)
        a = a[np.isfinite(a)]
        if c.lost_a is not None and sig.bimodal(c.lost_a, []):
            m, lo, hi = sig.median_diff_ci(a, np.zeros_like(a), rng)
        else:
            m, h = sig.t_interval(a)
            lo, hi = m - h, m + h
        ok = c.target is not None and bool(lo <= c.target <= hi)
        return Outcome(c, kind, m, lo, hi, holds=ok)
    if kind == "t":
        m, h = sig.t_interval(np.subtract(*sig.pairs(c.a, c.b)))
        return Outcome(c, kind, m, m - h, m + h, p=sig.paired_t(c.a, c.b)[1])
    if kind == "wilcoxon":
        m, lo, hi = sig.median_diff_ci(c.a, c.b, rng)
        return Outcome(c, kind, m, lo, hi, p=sig.wilcoxon_paired(c.a, c.b)[1])
    if kind == "mcnemar":
        only_a, only_b, p = sig.mcnemar_exact(c.lost_a, c.lost_b)
        return Outcome(c, kind, only_a - only_b, nan, nan, p=p)
    k_a, n_a, k_b, n_b = c.counts
    return Outcome(c, kind, k_a / n_a - k_b / n_b, nan, nan, p=sig.fisher_exact_lost(k_a, n_a, k_b, n_b))


def _keys(rule: Rule) -> list[str]:
    return [k for k in (rule.decides, rule.condition, rule.mechanism) if k]


def undecidable(c: Comparison, test: str) -> str:
    """Why ``test`` cannot decide comparison ``c`` ("" when it can): an interval without a target, a
    paired test without a pair, McNemar without lost flags, Fisher without counts."""
    if test == "interval" and c.target is None:
        return "an interval test without a target (the paper's number)"
    if test in PAIRED and (len(c.a) == 0 or len(c.b) == 0):
        return f"a paired test ({test}) without a pair (no b arm)"
    if test == "mcnemar" and (c.lost_a is None or c.lost_b is None):
        return "an exact McNemar test without the lost flags of both arms"
    if test == "fisher" and c.counts is None:
        return "a Fisher test without lost counts"
    return ""


def check_decidable(cl: Claim, evidence: dict) -> None:
    """Refuse (``ValueError``, one line naming the claim) a key the claim's rule names that is missing, empty,
    or holds a comparison its declared test cannot decide (:func:`undecidable`)."""
    for key in [*_keys(cl.rule), *[cl.rule.working] * bool(cl.rule.working)]:
        if not evidence.get(key):
            raise ValueError(f"claim {cl.id!r}: no evidence under {key!r}")
        for c in evidence[key]:
            if why := undecidable(c, c.test or cl.rule.test):
                raise ValueError(f"claim {cl.id!r}: {key!r} comparison {c.name!r}: {why} cannot decide it")


def holm_adjust(outcomes: list[Outcome], alpha: float = 0.05) -> int:
    """Holm over ``outcomes`` (one family): set each one's ``p_adj`` and ``holds`` (``p_adj < alpha``);
    return how many hold."""
    for o, padj in zip(outcomes, sig.holm([o.p for o in outcomes])):
        o.p_adj, o.holds = float(padj), bool(padj < alpha)
    return sum(o.holds for o in outcomes)


def decide(claims: list[Claim], evidence: dict, seed: int = 0) -> list[Verdict]:
    """Test every comparison the claims draw on, Holm-adjust each family, apply each rule (module
    docstring). ``evidence``: ``key -> [Comparison, ...]``; a key a rule names must be there, non-empty
    and decidable by its test (:func:`check_decidable`). ``seed`` seeds the bootstrap intervals."""
    ids = [c.id for c in claims]
    if len(set(ids)) != len(ids):
        raise ValueError(f"claim ids repeat: {sorted({i for i in ids if ids.count(i) > 1})}")
    for cl in claims:
        check_decidable(cl, evidence)
    rng = np.random.default_rng(seed)
    fam_of = {cl.id: cl.rule.family or f"claim:{cl.id}" for cl in claims}
    tested: dict[tuple[str, str], list[Outcome]] = {}  # (family, key): a key shared in a family counts once
    families: dict[str, list[Outcome]] = {}
    for cl in claims:
        for key in _keys(cl.rule):
            if (fam_of[cl.id], key) not in tested:
                outs = [test_one(c, c.test or cl.rule.test, rng) for c in evidence[key]]
                tested[(fam_of[cl.id], key)] = outs
                families.setdefault(fam_of[cl.id], []).extend(o for o in outs if o.test != "interval")
    alpha = {fam_of[cl.id]: cl.rule.alpha for cl in claims}
    for cl in claims:
        if cl.rule.alpha != alpha[fam_of[cl.id]]:
            raise ValueError(f"claim {cl.id!r}: family {fam_of[cl.id]!r} has two alphas")
    for name, fam in families.items():
        holm_adjust(fam, alpha[name])
    working = {cl.id: _working(cl, evidence, rng) for cl in claims}
    return [_verdict(cl, {k: tested[(fam_of[cl.id], k)] for k in _keys(cl.rule)}, working[cl.id]) for cl in claims]


def _working(cl: Claim, evidence: dict, rng: np.random.Generator) -> list[Outcome]:
    """The outcomes against the rule's working baselines, Holm-adjusted among themselves (printed, not deciding)."""
    if not cl.rule.working:
        return []
    outs = [test_one(c, c.test or cl.rule.test, rng) for c in evidence[cl.rule.working]]
    holm_adjust([o for o in outs if o.test != "interval"], cl.rule.alpha)
    return outs


def _enough(outs: list[Outcome], need: int | None) -> bool:
    n = sum(o.holds for o in outs)
    if need == "majority":
        return n > len(outs) / 2
    return n == len(outs) if need is None else n >= need


def broken(outs: list[Outcome], max_lost: float) -> list[Outcome]:
    """The outcomes whose baseline (arm ``b``, of an ordering test) lost more than ``max_lost`` of its runs."""
    lost = lambda o: np.asarray(o.comparison.lost_b, bool)
    paired = [o for o in outs if o.test in PAIRED and o.comparison.lost_b is not None]
    return [o for o in paired if len(lost(o)) and lost(o).mean() > max_lost]


def _verdict(cl: Claim, out: dict, working: list) -> Verdict:
    r = cl.rule
    dec = out[r.decides]
    tests = ", ".join(dict.fromkeys(TEST_NAMES[o.test] for os in [*out.values(), working] for o in os))
    v = Verdict(cl, NOT, r.text(), tests, deciding=dec, broken=broken(dec, r.max_lost), working=working)
    cap = (lambda lab: lab) if r.declared == "before" else (lambda lab: CAPPED.get(lab, lab))
    if _enough(dec, r.need) and not v.broken:
        v.label = cap(REPRODUCED)
        return v
    for kind, key, label in (("condition", r.condition, RECOVERED), ("mechanism", r.mechanism, MECHANISM)):
        if key and _enough(out[key], None) and not (label == RECOVERED and broken(out[key], r.max_lost)):
            v.label, v.support = cap(label), out[key]
            v.gap = "; ".join(o.text() for o in dec) if label == RECOVERED else ""
            return v
        if key:
            v.tried[kind] = out[key]
    return v


def counts(verdicts: list[Verdict]) -> str:
    """``"1 reproduced, 2 recovered under a stated condition, ... (of N claims)"``."""
    return (
        ", ".join(f"{sum(v.label == lab for v in verdicts)} {lab}" for lab in LABELS) + f" (of {len(verdicts)} claims)."
    )
