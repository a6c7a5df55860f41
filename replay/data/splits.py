"""Training and test sets for ``replay tune``: by time segment of one log, by sequence, or by seed.

:func:`split_views` turns a split specification into ``(train, test)``, two
dicts a tune adds to its configurations:

* ``{"segment": 0.6}`` (the training share of the duration, ``0 < share < 1``)
  -> ``({"segment": "0:0.6"}, {"segment": "0.6:1"})``: dataset parameters
  (:mod:`replay.data.views`); the two segments share no sample (``[0, 0.6·D)`` and
  ``[0.6·D, D]``).
* ``{"train": [ids], "test": [ids]}`` -> ``({"datasets": [...]}, {"datasets": [...]})``:
  whole sequences (dataset ids, or files), each list non-empty, no id twice.
* ``{"seeds": S}`` for simulated data -> ``({"seed": S}, {"seed": S + 1})``, or
  ``{"seeds": [S_train, S_test]}``: master seeds. Every draw of a simulator comes
  from ``(seed, run, stream)`` (:mod:`replay.util.seeds`), so two different master
  seeds give disjoint sets of Monte Carlo runs whatever the run ranges: the test
  runs ``0..N-1`` under ``S + 1`` are not the training runs ``0..N-1`` under ``S``.
  Both seeds must be integers ``>= 0``. For simulated datasets only: a recording's
  samples are the same under every seed (:func:`check_disjoint` with ``dataset``
  refuses it).

:func:`check_disjoint` refuses, in one line, a training and a test set that
share data: the same sequence with overlapping views (time segments or windows
in seconds that intersect, any other pair of views of one sequence), or the same
master seed; with ``allow_overlap=True`` it returns the overlap's description
instead (a tune then flags every row).
"""

from __future__ import annotations

from replay.data import views
from replay.util.errors import ReplayError
from replay.data.dataset_ref import simulated

SEED_MAX = 2**63 - 1


def split_views(spec: dict) -> tuple[dict, dict]:
    """``(train, test)`` of a split specification (module docstring); one line on a bad one."""
    if not isinstance(spec, dict) or len(spec.keys() & {"segment", "train", "test", "seeds"}) == 0:
        raise ReplayError(
            f"split: expected {{segment = SHARE}}, {{train = [ids], test = [ids]}} or {{seeds = S}} (got {spec!r})"
        )
    kinds = [k for k in ("segment", "seeds") if k in spec] + (["train/test"] if {"train", "test"} & spec.keys() else [])
    extra = sorted(set(spec) - {"segment", "train", "test", "seeds"})
    if len(kinds) != 1 or extra:
        raise ReplayError(f"split: give exactly one of segment, train/test, seeds (got {', '.join(sorted(spec))})")
    if "segment" in spec:
        share = spec["segment"]
        if isinstance(share, bool) or not isinstance(share, (int, float)) or not 0 < share < 1:
            raise ReplayError(
                f"split: segment must be the training share of the duration, a number in (0, 1) (got {share!r})"
            )
        cut = views.check({"segment": f"0:{float(share)!r}"})["segment"].split(":")[1]
        return {"segment": f"0:{cut}"}, {"segment": f"{cut}:1"}
    if "seeds" in spec:
        seeds = spec["seeds"]
        pair = [seeds, seeds + 1] if _seed(seeds) else seeds
        if not (isinstance(pair, (list, tuple)) and len(pair) == 2 and all(_seed(s) for s in pair)):
            raise ReplayError(
                f"split: seeds must be a master seed S (test S + 1) or [S_train, S_test], "
                f"integers in [0, {SEED_MAX}] (got {seeds!r})"
            )
        train, test = {"seed": int(pair[0])}, {"seed": int(pair[1])}
        check_disjoint(train, test)
        return train, test
    sides = []
    for side in ("train", "test"):
        ids = spec.get(side)
        if not isinstance(ids, (list, tuple)) or not ids or not all(isinstance(i, str) and i for i in ids):
            raise ReplayError(f"split: {side} must be a non-empty list of dataset ids (got {ids!r})")
        twice = sorted({i for i in ids if list(ids).count(i) > 1})
        if twice:
            raise ReplayError(f"split: {side} names {twice[0]} twice")
        sides.append({"datasets": list(ids)})
    check_disjoint(*sides)
    return sides[0], sides[1]


def _seed(s) -> bool:
    return isinstance(s, int) and not isinstance(s, bool) and 0 <= s <= SEED_MAX - 1


def check_disjoint(train: dict, test: dict, allow_overlap: bool = False, dataset: str | None = None) -> str | None:
    """None when ``train`` and ``test`` (dicts as :func:`split_views` gives, possibly with view
    parameters beside ``datasets``) share no data; else ReplayError naming the overlap, or with
    ``allow_overlap`` its description. ``dataset``: the sequence both sides view when they name none."""
    overlap = _overlap(train, test, dataset)
    if overlap is None or allow_overlap:
        return overlap
    raise ReplayError(
        f"the training and test sets overlap: {overlap} (pass --allow-overlap to tune anyway; "
        "every row is then flagged)"
    )


def _overlap(train: dict, test: dict, dataset) -> str | None:
    if "seed" in train or "seed" in test:
        if train.get("seed") == test.get("seed"):
            return f"both use master seed {train.get('seed')}"
        recorded = [
            d
            for d in train.get("datasets", [dataset]) + test.get("datasets", [dataset])
            if d is not None and not _simulated(d)
        ]
        return f"{recorded[0]} is a recording: its samples are the same under every seed" if recorded else None
    common = [d for d in train.get("datasets", [dataset]) if d in test.get("datasets", [dataset])]
    if not common:
        return None
    a, b = views.split(train)[0], views.split(test)[0]
    a.pop("rate", None), b.pop("rate", None)
    if _apart(a, b):
        return None
    shown = ", ".join(str(d) for d in common if d is not None) or "the dataset"
    return f"{shown} in both" + (f" ({_text(a)} and {_text(b)})" if a or b else "")


def _simulated(dataset: str) -> bool:
    return simulated(dataset)


def _apart(a: dict, b: dict) -> bool:
    """Whether two views of one sequence certainly share no sample: segments (and windows in
    seconds) of the same kind whose ranges do not intersect, nothing else beside them."""
    for key in ("segment", "window"):
        if set(a) == set(b) == {key}:
            (lo_a, hi_a), (lo_b, hi_b) = _range(key, a[key]), _range(key, b[key])
            if a[key].startswith("#") != b[key].startswith("#"):
                return False
            return hi_a <= lo_b or hi_b <= lo_a
    return False


def _range(key: str, text: str) -> tuple[float, float]:
    text = views.check({key: text})[key]
    lo, hi = text.lstrip("#").split(":")
    return float(lo or 0), float(hi or "inf")


def _text(v: dict) -> str:
    return ", ".join(f"{k} {x}" for k, x in sorted(v.items())) or "all of it"
