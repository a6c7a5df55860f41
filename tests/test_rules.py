"""The verdict framework on synthetic evidence (issue 27 acceptance): rules fixed before the data,
Holm over each family, rank tests where lost runs make errors bimodal, the one renderer."""
from functools import partial

import numpy as np
import pytest

from replay.reproduce import render, rules
from replay.reproduce.rules import MECHANISM, NOT, RECOVERED, REPRODUCED, Claim, Comparison, Rule, decide, holm_adjust
from replay.scoring import significance as sig

# These tests decide rules declared before the data (the cap of a post-hoc rule: test_reproduce_declared.py).
Rule = partial(Rule, declared="before")


def claim(rule, cid="c"):
    return Claim(cid, "A < B", "A < B", rule, "#e-c")


def null_cells(n_cells=12, runs=10, seed=3):
    """12 cells where A and B are the same filter (no effect): the smallest p is about 1/12."""
    rng = np.random.default_rng(seed)
    cells = []
    for i in range(n_cells):
        b = rng.normal(1.0, 0.1, runs)
        cells.append(Comparison(f"cell {i}", b + rng.normal(0, 0.05, runs), b))
    return cells


def chance_cells():
    """A null family of 12 cells of which exactly one is nominally significant (p < 0.05)."""
    for seed in range(200):
        cells = null_cells(seed=seed)
        p = [sig.paired_t(c.a, c.b)[1] for c in cells]
        if sum(x < 0.05 for x in p) == 1 and min(p) > 0.05 / 12:
            return cells, min(p)
    raise AssertionError("no seed gives one chance cell")


def test_a_claim_true_in_1_of_12_cells_by_chance_is_not_reproduced():
    cells, pmin = chance_cells()
    assert pmin < 0.05  # one cell "holds" on its own
    for need in (None, 1):  # every cell, or any one cell: both Holm-adjusted over the 12
        rule = Rule("grid", "the 12 cells", "paired per-run RMSE A - B", test="t", need=need)
        v, = decide([claim(rule)], {"grid": cells})
        assert v.label == NOT
        assert min(o.p_adj for o in v.deciding) == pytest.approx(min(12 * pmin, 1.0))
        assert sum(o.holds for o in v.deciding) == 0


def test_a_sweep_as_the_stated_condition_is_adjusted_over_its_cells():
    cells, _ = chance_cells()
    lucky = min(cells, key=lambda c: sig.paired_t(c.a, c.b)[1])
    rule = Rule("paper", "the paper's setting", "A - B", test="t", condition="grid", condition_text="the sweep")
    v, = decide([claim(rule)], {"paper": [cells[0] if cells[0] is not lucky else cells[1]], "grid": cells})
    assert v.label == NOT  # the condition is every cell of the sweep, adjusted: no rescue



def bimodal_pair():
    """20 runs: B loses 5 (error 50 against ~1), A loses none; on the 15 tracked runs A is 0.25
    better in 5 and 0.25 worse in 10: the median difference is 0, the mean difference -12."""
    b = np.full(20, 1.0)
    b[15:] = 50.0
    a = np.full(20, 1.0)
    a[:5] -= 0.25
    a[5:15] += 0.25
    return a, b, np.zeros(20, bool), b > 20


def test_a_bimodal_pair_with_equal_medians_is_not_significant():
    a, b, lost_a, lost_b = bimodal_pair()
    assert np.median(a - b) == 0.0
    assert sig.paired_t(a, b)[1] < 0.05  # what a t-test on the means would say
    c = Comparison("A - B", a, b, lost_a, lost_b)
    v, = decide([claim(Rule("x", "one cell", "per-run RMSE A - B"))], {"x": [c]})
    o, = v.deciding
    assert o.test == "wilcoxon" and v.tests == "Wilcoxon signed-rank"
    assert o.p == pytest.approx(sig.wilcoxon_paired(a, b)[1]) and o.p > 0.05
    assert o.estimate == 0.0 and o.lo <= 0.0 <= o.hi
    assert v.label == NOT


def mcnemar(k):
    """A never lost, B lost alone in k runs: exact one-sided p = 0.5 ** k."""
    lost_b = np.zeros(20, bool)
    lost_b[:k] = True
    return Comparison(f"k={k}", lost_a=np.zeros(20, bool), lost_b=lost_b)


def test_holm_in_decide_matches_a_hand_computation():
    ev = {"x": [mcnemar(5), mcnemar(6), mcnemar(4)]}  # raw p 0.03125, 0.015625, 0.0625
    v, = decide([claim(Rule("x", "3 cells", "lost runs", test="mcnemar"))], ev)
    # sorted 0.015625 x 3 = 0.046875; 0.03125 x 2 = 0.0625; 0.0625 x 1 -> 0.0625 (monotone)
    assert [o.p for o in v.deciding] == pytest.approx([0.03125, 0.015625, 0.0625])
    assert [o.p_adj for o in v.deciding] == pytest.approx([0.0625, 0.046875, 0.0625])
    assert [o.holds for o in v.deciding] == [False, True, False] and v.label == NOT
    v, = decide([claim(Rule("x", "3 cells", "lost runs", test="mcnemar", need=1))], ev)
    assert v.label == REPRODUCED


def test_holm_adjust_sets_adjusted_p_and_counts_what_holds():
    rng = np.random.default_rng(0)
    outs = [rules.test_one(mcnemar(k), "mcnemar", rng) for k in (5, 6, 4)]
    assert holm_adjust(outs, 0.05) == 1
    assert [o.p_adj for o in outs] == pytest.approx([0.0625, 0.046875, 0.0625])
    assert holm_adjust(outs, 0.07) == 3


def test_a_shared_family_adjusts_across_claims():
    ev = {"x": [mcnemar(6)], "y": [mcnemar(6)]}
    own = decide([claim(Rule("x", "c", "s", test="mcnemar"), "a"), claim(Rule("y", "c", "s", test="mcnemar"), "b")],
                 ev)
    assert [v.label for v in own] == [REPRODUCED, REPRODUCED]
    fam = decide([claim(Rule("x", "c", "s", test="mcnemar", family="f", alpha=0.02), "a"),
                  claim(Rule("y", "c", "s", test="mcnemar", family="f", alpha=0.02), "b")], ev)
    assert [v.deciding[0].p_adj for v in fam] == pytest.approx([0.03125, 0.03125])
    assert [v.label for v in fam] == [NOT, NOT]


def test_recovered_and_mechanism_need_their_declared_evidence():
    rng = np.random.default_rng(0)
    base = rng.normal(1, 0.1, 12)
    same = Comparison("paper's setting", base + rng.normal(0, 0.01, 12), base)
    better = Comparison("small Q", base - 0.5 + rng.normal(0, 0.01, 12), base)
    r = Rule("p", "paper", "A - B", test="t", condition="q", condition_text="Q 100x smaller")
    v, = decide([claim(r)], {"p": [same], "q": [better]})
    assert v.label == RECOVERED and "paper's setting: mean" in v.gap
    r = Rule("p", "paper", "A - B", test="t", mechanism="m", mechanism_text="without the grey particles")
    v, = decide([claim(r)], {"p": [same], "m": [better]})
    assert v.label == MECHANISM
    with pytest.raises(ValueError, match="no evidence under 'q'"):
        decide([claim(Rule("p", "paper", "A - B", condition="q", condition_text="x"))], {"p": [same]})
    with pytest.raises(ValueError, match="declared together"):
        Rule("p", "paper", "A - B", condition="q")
    with pytest.raises(ValueError, match="rule test"):
        Rule("p", "paper", "A - B", test="any cell")


def test_interval_rule_holds_the_papers_number():
    x = np.array([1.0, 1.2, 0.9, 1.1, 1.05])
    ok = Comparison("ours", x, target=1.0)
    off = Comparison("ours", x, target=2.0)
    assert decide([claim(Rule("x", "c", "RMSE", test="interval"))], {"x": [ok]})[0].label == REPRODUCED
    v, = decide([claim(Rule("x", "c", "RMSE", test="interval"))], {"x": [off]})
    assert v.label == NOT and np.isnan(v.deciding[0].p_adj) and "vs paper 2" in v.deciding[0].text()


def test_render_opens_with_the_verdicts_and_fills_every_placeholder(tmp_path):
    v = decide([claim(Rule("x", "3 cells", "lost runs", test="mcnemar"))], {"x": [mcnemar(6)]})
    t = tmp_path / "t.md"
    t.write_text("# Paper\n\n## Verdict\n\n${verdicts}\n\n## Setup\n\n${setup} costs $$5\n")
    out = render.render(t, {"setup": "N = 10"}, v)
    assert out.index("| claim | paper | verdict |") < out.index("## Setup")
    assert "**reproduced**" in out and "N = 10 costs $5" in out and "1 reproduced, 0 recovered" in out
    with pytest.raises(ValueError, match=r"without a value \['setup'\]"):
        render.render(t, {}, v)
    with pytest.raises(ValueError, match=r"without a placeholder \['extra'\]"):
        render.render(t, {"setup": "", "extra": 1}, v)
    t.write_text("# Paper\n\n## Setup\n\n${verdicts}\n")
    with pytest.raises(ValueError, match="before the verdict table"):
        render.render(t, {}, v)
    assert render.anchor_tag("#e-depth") == '<a id="e-depth"></a>'
    assert render.table(["a", "b"], [[1, "x|y"]]) == "| a | b |\n|---|---|\n| 1 | x\\|y |"


def test_a_diverged_run_is_the_worst_error_and_lost():
    from types import SimpleNamespace
    a = SimpleNamespace(runs=[{"pos_rmse": 1.0, "lost": False, "diverged": False}] * 9
                        + [{"pos_rmse": float("nan"), "lost": False, "diverged": True}])
    b = SimpleNamespace(runs=[{"pos_rmse": 2.0, "lost": False, "diverged": False}] * 10)
    vals, lost = rules.per_run(a)
    assert np.isinf(vals[-1]) and lost.tolist() == [False] * 9 + [True]
    c = rules.paired_runs("A - B", a, b)
    o = rules.test_one(c, "auto", np.random.default_rng(0))
    assert o.test == "wilcoxon" and o.p == pytest.approx(sig.wilcoxon_paired(c.a, c.b)[1])
    assert o.p == pytest.approx(stats_wilcoxon_less([-1.0] * 9 + [np.inf]))
    assert np.isnan(rules.test_one(c, "t", np.random.default_rng(0)).p)  # no t-test over an infinite error


def stats_wilcoxon_less(d):
    from scipy import stats
    return stats.wilcoxon(np.nan_to_num(np.asarray(d), posinf=1e300), alternative="less").pvalue


def test_majority_rule_counts_holm_adjusted_comparisons():
    ev = {"x": [mcnemar(6), mcnemar(6), mcnemar(1)]}  # Holm: 0.046875, 0.046875, 0.5
    v, = decide([claim(Rule("x", "3 pairs", "lost runs", test="mcnemar", need="majority"))], ev)
    assert [o.holds for o in v.deciding] == [True, True, False] and v.label == REPRODUCED
    assert "more than half of the comparisons significant" in v.rule
    v, = decide([claim(Rule("x", "3 pairs", "lost runs", test="mcnemar", need="majority"))],
                {"x": [mcnemar(6), mcnemar(1), mcnemar(1)]})
    assert v.label == NOT
    with pytest.raises(ValueError, match="rule need"):
        Rule("x", "c", "s", need="most")


def test_a_condition_tried_and_not_met_is_printed_beside_the_verdict():
    rng = np.random.default_rng(0)
    base = rng.normal(1, 0.1, 12)
    same = Comparison("paper's setting", base + rng.normal(0, 0.01, 12), base)
    worse = Comparison("small Q", base + 0.5, base)
    v, = decide([claim(Rule("p", "paper", "A - B", test="t", condition="q", condition_text="Q small",
                            mechanism="m", mechanism_text="ablation"))], {"p": [same], "q": [worse], "m": [same]})
    assert v.label == NOT and [o.comparison.name for o in v.tried["condition"]] == ["small Q"]
    row = render.verdict_table([v]).splitlines()[2]
    assert "Stated condition, not met: small Q: mean 0.5" in row and "Ablation, not shown: paper's setting" in row
    v, = decide([claim(Rule("p", "paper", "A - B", test="t", condition="q", condition_text="Q small"))],
                {"p": [same], "q": [Comparison("small Q", base - 0.5, base)]})
    assert v.label == RECOVERED and v.tried == {}


def test_interval_text_without_a_paper_number_and_with_lost_runs():
    """An interval comparison with no paper number prints n/a (it cannot hold), and with a lost run its
    estimate is the median (the bootstrap interval test_one takes then), said as such."""
    import numpy as np

    from replay.reproduce.rules import Comparison, test_one

    rng = np.random.default_rng(0)
    c = Comparison("cell", [1.0, 2.0, 3.0, 4.0], None, lost_a=[False, False, False, True], lost_b=None, target=None)
    o = test_one(c, "interval", rng)
    assert not o.holds and "vs paper n/a" in o.text() and "median" in o.text()
