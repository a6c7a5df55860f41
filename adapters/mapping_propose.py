"""The mapping proposed for a recording's topics, for the obvious cases (:func:`propose`; docs/bags.md)."""

from __future__ import annotations

import re


from .mapping import Entry, Mapping
from .rosmsg import kind_of, normalize_type


def propose(topics: dict[str, tuple[str, int]]) -> Mapping:
    """A mapping for the obvious cases, from ``{topic: (type, count)}``.

    Each supported topic becomes a channel named after its kind (gps, odom, imu,
    depth, dvl, pose; numbered when a kind repeats). The reference is a pose or
    odometry topic named like ground truth (``truth``, ``groundtruth``,
    ``ground_truth``, ``gt``, ``reference``, ``mocap``, ``vicon``); failing
    that, a single NavSatFix (the fix track as reference, see docs/bags.md).
    Beside a ground-truth reference, every other pose topic is also proposed as a
    recorded estimate (``[estimates]``, named after its topic), as evo would score it.
    """
    names = {"navsatfix": "gps", "odometry": "odom", "imu": "imu", "pressure": "depth", "twist": "dvl", "pose": "pose"}
    entries, used = [], {}
    truth_words = ("groundtruth", "ground_truth", "truth", "gt", "reference", "mocap", "vicon")
    reference = None
    for topic, (typ, count) in topics.items():
        kind = kind_of(typ)
        if kind not in names or count == 0:  # TF needs a named pair, a Path is an estimate: not proposed
            continue
        base = topic.strip("/").lower().replace("/", "_")
        if (
            reference is None
            and kind in ("pose", "odometry")
            and any(w == base or base.endswith(w) or base.startswith(w) for w in truth_words)
        ):
            reference = Entry("position", topic, normalize_type(typ), True)
            continue
        stem = names[kind]
        used[stem] = used.get(stem, 0) + 1
        name = stem if used[stem] == 1 else f"{stem}{used[stem]}"
        entries.append(Entry(name, topic, normalize_type(typ)))
    if reference is None:
        fixes = [e for e in entries if e.type and kind_of(e.type) == "navsatfix"]
        if len(fixes) == 1:
            reference = Entry("position", fixes[0].topic, fixes[0].type, True)
    estimates = []
    if reference is not None:
        entries.append(reference)
        if kind_of(reference.type) != "navsatfix":  # a ground truth: the other poses are estimates to score
            for e in entries:
                est = re.sub(r"[^A-Za-z0-9_.+-]", "_", e.topic.strip("/")).lstrip("_.+-")[:64] or e.name
                est = est if est != "none" else "none_"  # recorded:none means no estimate
                if not e.reference and kind_of(e.type) == "pose" and est not in {x.name for x in estimates}:
                    estimates.append(Entry(est, e.topic, e.type, estimate=True))
    return Mapping(entries, estimates=estimates)
