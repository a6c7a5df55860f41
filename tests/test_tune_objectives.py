"""replay.tune.objectives: the grid rule "lowest RMSE, then the ANEES closest to its dof among near ties"."""

import math

from replay.tune.objectives import lowest_then_consistent

INF, NAN = math.inf, math.nan


def test_lowest_rmse_then_anees_closest_to_dof_among_ties():
    rmse = [5.0, 5.04, 5.06, 7.0]
    anees = [400.0, 3.5, 3.0, 3.0]
    assert lowest_then_consistent(rmse, anees, 0.01, 3.0) == 1  # 5.06 is 1.2 % above: out of the tie
    assert lowest_then_consistent(rmse, anees, 0.02, 3.0) == 2
    assert lowest_then_consistent(rmse, anees, 0.0, 3.0) == 0
    assert lowest_then_consistent([1.0, 1.0], [2.0, 4.0], 0.0, 3.0) == 0  # equal distance: the first


def test_diverged_never_chosen_nan_anees_farthest_none_when_all_diverged():
    assert lowest_then_consistent([INF, 2.0, 2.0], [3.0, NAN, 50.0], 0.01, 3.0) == 2
    assert lowest_then_consistent([NAN, 2.0], [3.0, 9.0], 0.01, 3.0) == 1
    assert lowest_then_consistent([NAN, INF], [3.0, 3.0], 0.01, 3.0) is None
