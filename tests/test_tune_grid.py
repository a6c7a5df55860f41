"""replay.tune.grid: a grid's points; the rule "lowest RMSE, then the ANEES closest to its dof among near ties"."""

import math

from replay.tune.grid import lowest_then_consistent, points

NAN = math.nan


def rows(rmse, anees, diverged=()):
    return [{"pos_rmse": r, "anees": a, "diverged": int(i in diverged)} for i, (r, a) in enumerate(zip(rmse, anees))]


def test_lowest_rmse_then_anees_closest_to_dof_among_ties():
    grid = rows([5.0, 5.04, 5.06, 7.0], [400.0, 3.5, 3.0, 3.0])
    assert lowest_then_consistent(grid, 0.01, 3.0) == 1  # 5.06 is 1.2 % above: out of the tie
    assert lowest_then_consistent(grid, 0.02, 3.0) == 2
    assert lowest_then_consistent(grid, 0.0, 3.0) == 0
    assert lowest_then_consistent(rows([1.0, 1.0], [2.0, 4.0]), 0.0, 3.0) == 0  # equal distance: the first


def test_diverged_never_chosen_missing_anees_farthest_none_when_all_diverged():
    assert lowest_then_consistent(rows([1.0, 2.0, 2.0], [3.0, NAN, 50.0], diverged=[0]), 0.01, 3.0) == 2
    assert lowest_then_consistent(rows([2.0, 2.0], [None, 9.0]), 0.01, 3.0) == 1
    assert lowest_then_consistent(rows([NAN, 2.0], [3.0, 9.0]), 0.01, 3.0) == 1
    assert lowest_then_consistent(rows([NAN, 1.0], [3.0, 3.0], diverged=[1]), 0.01, 3.0) is None


def test_points_every_combination_last_parameter_fastest():
    assert points({"q": [0.1, 1.0], "r": [3.0, 4.0, 5.0]})[:4] == [
        {"q": 0.1, "r": 3.0},
        {"q": 0.1, "r": 4.0},
        {"q": 0.1, "r": 5.0},
        {"q": 1.0, "r": 3.0},
    ]
    assert len(points({"q": [1, 2], "r": [3, 4, 5], "s": [6]})) == 6 and points({}) == [{}]
