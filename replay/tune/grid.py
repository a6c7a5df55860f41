"""A declared grid of configurations (a list of values per parameter): its points and the rule that picks one.

``replay tune`` searches a space with a sampler (:mod:`.study`); a reproduction that declares a small grid
evaluates every point (:func:`points`) and picks one from their leaderboard rows (:func:`lowest_then_consistent`).
"""

from __future__ import annotations

import itertools
import math


def points(grid: dict[str, list]) -> list[dict]:
    """Every combination of the grid's lists, the last parameter varying fastest: ``{"q": [1, 2], "r": [3]}``
    -> ``[{"q": 1, "r": 3}, {"q": 2, "r": 3}]``."""
    return [dict(zip(grid, values)) for values in itertools.product(*grid.values())]


def lowest_then_consistent(rows: list[dict], tie: float, dof: float) -> int | None:
    """Index of the chosen leaderboard row (:mod:`replay.scoring.summary`) of a grid's points: the lowest
    ``pos_rmse`` and, among the rows within the fraction ``tie`` of it (over noise scales an RMSE fixes only
    the ratio of Q to R), the ``anees`` closest to ``dof`` (consistent; the first in order at equal
    distance). A row with a diverged run or a non-finite RMSE is never chosen (as a diverged configuration
    scores ``inf`` in :mod:`.objectives`), a missing or non-finite ANEES is the farthest; None when no row
    qualifies."""
    rmse = [math.inf if r.get("diverged") else float(r["pos_rmse"]) for r in rows]
    finite = [x for x in rmse if math.isfinite(x)]
    if not finite:
        return None
    near = [i for i, x in enumerate(rmse) if x <= (1 + tie) * min(finite)]
    anees = [float(r.get("anees") or math.nan) for r in rows]
    distance = [abs(a - dof) if math.isfinite(a) else math.inf for a in anees]
    return min(near, key=distance.__getitem__)
