"""Training and test data of ``replay tune``: which datasets (with their view parameters) and seeds.

* ``--train-segment F``: one log, its first F of the duration for training and the rest for
  the test (dataset parameter ``segment``, ``"0:F"`` and ``"F:1"``: the views of issue 25 item 1);
* ``--train ID,ID --test ID,ID``: by sequence;
* ``--split seeds`` (simulated data): one dataset, training on master seed S and testing on S + 1
  (every run's streams are drawn from (seed, run, stream): disjoint).

Overlap (the same data on both sides) is refused unless ``allow_overlap``; then every row says so.
"""
from __future__ import annotations

from dataclasses import dataclass

from replay.util.errors import ReplayError

VIEW_KEYS = ("rate", "window", "segment")


@dataclass
class Split:
    train: list  # [(dataset id, dataset params)]
    test: list
    train_seed: int | None
    test_seed: int | None
    tuned_on: str
    tested_on: str
    overlap: bool = False


def _fraction(text: str) -> float:
    try:
        f = float(text)
    except (TypeError, ValueError):
        f = float("nan")
    if not 0 < f < 1:
        raise ReplayError(f"--train-segment {text}: expected a fraction of the log's duration in (0, 1), e.g. 0.6")
    return f


def _describe(parts, seed) -> str:
    text = " + ".join(d + "".join(f" {k}={v}" for k, v in sorted(p.items())) for d, p in parts)
    return text + (f" (seed {seed})" if seed is not None else "")


def make(dataset: str | None, view: dict, *, train_segment=None, train=None, test=None, split=None,
         seed: int = 0, allow_overlap: bool = False, is_sim=None) -> Split:
    """The split the options ask for (exactly one way), checked for overlap."""
    ways = [w for w, v in (("--train-segment", train_segment), ("--train/--test", train or test),
                           ("--split", split)) if v]
    if len(ways) != 1:
        raise ReplayError("give exactly one of --train-segment F, --train IDS --test IDS, --split seeds"
                          + (f" (got {', '.join(ways)})" if ways else ""))
    if train_segment is not None:
        if not dataset:
            raise ReplayError("--train-segment needs a DATASET")
        f = _fraction(train_segment)
        if "segment" in view:
            raise ReplayError("--train-segment: the dataset view already has a segment; give one or the other")
        a = [(dataset, {**view, "segment": f"0:{f:g}"})]
        b = [(dataset, {**view, "segment": f"{f:g}:1"})]
        s = Split(a, b, None, None, _describe(a, None), _describe(b, None))
    elif train or test:
        if not (train and test):
            raise ReplayError("--train and --test go together (comma-separated dataset ids each)")
        if dataset:
            raise ReplayError("give either DATASET (with --train-segment or --split) or --train/--test, not both")
        a = [(d.strip(), dict(view)) for d in train.split(",") if d.strip()]
        b = [(d.strip(), dict(view)) for d in test.split(",") if d.strip()]
        s = Split(a, b, None, None, _describe(a, None), _describe(b, None))
    else:
        if split != "seeds":
            raise ReplayError(f"--split {split!r}: the only split by option is 'seeds' (simulated data)")
        if not dataset or (is_sim is not None and not is_sim(dataset)):
            raise ReplayError(f"--split seeds: {dataset or 'no DATASET'} is not a simulated dataset (its runs would "
                              "share the same recording); use --train-segment or --train/--test")
        a, b = [(dataset, dict(view))], [(dataset, dict(view))]
        s = Split(a, b, seed, seed + 1, _describe(a, seed), _describe(b, seed + 1))
    s.overlap = overlaps(s)
    if s.overlap and not allow_overlap:
        raise ReplayError(f"training data ({s.tuned_on}) and test data ({s.tested_on}) overlap: a filter would be "
                          "scored on data it was tuned on; pass --allow-overlap to do it anyway (every row says so)")
    return s


def overlaps(s: Split) -> bool:
    """Whether some training data is test data (the views' own check when present)."""
    if s.train_seed is not None and s.train_seed != s.test_seed:
        return False
    try:
        from replay.splits import check_disjoint  # issue 25 item 1 (views)
    except ImportError:
        check_disjoint = None
    for d, p in s.train:
        for e, q in s.test:
            if d != e:
                continue
            if check_disjoint is not None:
                try:
                    check_disjoint([(d, p)], [(e, q)])
                    continue
                except ReplayError:
                    return True
                except TypeError:
                    pass
            if not _segments_apart(p, q):
                return True
    return False


def _segments_apart(p: dict, q: dict) -> bool:
    """Two views of one log apart by their segments (``"A:B"`` fractions), other view keys equal."""
    if {k: v for k, v in p.items() if k != "segment"} != {k: v for k, v in q.items() if k != "segment"}:
        return False  # another window or rate: cannot tell here; treated as overlapping
    try:
        (a0, a1), (b0, b1) = (tuple(float(x) for x in str(v.get("segment", "0:1")).split(":")) for v in (p, q))
    except ValueError:
        return False
    return a1 <= b0 or b1 <= a0
