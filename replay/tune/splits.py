"""Training and test data of ``replay tune``: which datasets (with their view parameters) and seeds.

* ``--train-segment F``: one log, its first F of the duration for training and the rest for
  the test (dataset parameter ``segment``, ``"0:F"`` and ``"F:1"``: the views of issue 25 item 1);
* ``--train ID,ID --test ID,ID``: by sequence;
* ``--split seeds`` (simulated data): one dataset, training on master seed S and testing on S + 1
  (every run's streams are drawn from (seed, run, stream): disjoint).

Overlap (the same data on both sides, decided on content by :mod:`.parts` once the parts are read)
is refused unless ``allow_overlap``; then every row says so.
"""

from __future__ import annotations

from dataclasses import dataclass

from replay.util.errors import ReplayError
from . import parts
from replay.data.splits import split_views


@dataclass
class Split:
    train: list  # [(dataset id, dataset params)]
    test: list
    train_seed: int | None
    test_seed: int | None
    tuned_on: str
    tested_on: str
    overlap: str | None = None  # what train and test share (allowed with --allow-overlap)
    train_option: str = ""  # the option that made each side, named in refusals
    test_option: str = ""


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


def make(
    dataset: str | None,
    view: dict,
    *,
    train_segment=None,
    train=None,
    test=None,
    split=None,
    seed: int = 0,
) -> Split:
    """The split the options ask for (exactly one way; its parts and overlap are checked by :func:`check_parts`)."""
    ways = [
        w for w, v in (("--train-segment", train_segment), ("--train/--test", train or test), ("--split", split)) if v
    ]
    if len(ways) != 1:
        raise ReplayError(
            "give exactly one of --train-segment F, --train IDS --test IDS, --split seeds"
            + (f" (got {', '.join(ways)})" if ways else "")
        )
    if train_segment is not None:
        if not dataset:
            raise ReplayError("--train-segment needs a DATASET")

        if "segment" in view:
            raise ReplayError("--train-segment: the dataset view already has a segment; give one or the other")
        tr, te = split_views({"segment": _fraction(train_segment)})
        a, b = [(dataset, {**view, **tr})], [(dataset, {**view, **te})]
        s = Split(a, b, None, None, _describe(a, None), _describe(b, None))
        s.train_option = s.test_option = f"--train-segment {train_segment}"
    elif train or test:
        if not (train and test):
            raise ReplayError("--train and --test go together (comma-separated dataset ids each)")
        if dataset:
            raise ReplayError("give either DATASET (with --train-segment or --split) or --train/--test, not both")
        a = [(d.strip(), dict(view)) for d in train.split(",") if d.strip()]
        b = [(d.strip(), dict(view)) for d in test.split(",") if d.strip()]
        s = Split(a, b, None, None, _describe(a, None), _describe(b, None))
        s.train_option, s.test_option = f"--train {train}", f"--test {test}"
    else:
        if split != "seeds":
            raise ReplayError(f"--split {split!r}: the only split by option is 'seeds' (simulated data)")
        if not dataset:
            raise ReplayError("--split seeds needs a DATASET (simulated)")
        a, b = [(dataset, dict(view))], [(dataset, dict(view))]
        s = Split(a, b, seed, seed + 1, _describe(a, seed), _describe(b, seed + 1))
        s.train_option = s.test_option = "--split seeds"
    return s


def check_parts(s: Split, *, seed: int, first, data_dir, refs: dict, allow_overlap: bool) -> None:
    """Read every part (:func:`replay.tune.parts.read`: each holds enough samples), set ``s.overlap``
    from their content and refuse it unless ``allow_overlap``."""
    read = {}
    for side, items, part_seed, option in (
        ("training", s.train, s.train_seed, s.train_option),
        ("test", s.test, s.test_seed, s.test_option),
    ):
        part_seed = seed if part_seed is None else part_seed
        read[side] = []
        for d, p in items:
            desc = _describe([(d, p)], part_seed if refs[d].is_sim else None)
            where = f"{option}: the {side} part {desc}"
            read[side].append(
                (desc, parts.read(d, p, seed=part_seed, first=first, data_dir=data_dir, ref=refs[d], where=where))
            )
    s.overlap = parts.overlap(read["training"], read["test"])
    if s.overlap and s.train_seed is not None:  # simulations under two seeds never meet: a recording
        s.overlap += " (a recording: its samples are the same under every seed)"
    if s.overlap and not allow_overlap:
        raise ReplayError(
            f"training data ({s.tuned_on}) and test data ({s.tested_on}) overlap: {s.overlap}; a "
            "filter would be scored on data it was tuned on (pass --allow-overlap to tune anyway: "
            "every row is then flagged)"
        )
