"""What one mapping entry reads from its topic: the messages (a TF pair, a Path's poses, or the
topic's own messages), their stamps, and the kind of converter that reads them."""

from __future__ import annotations

import numpy as np

from replay.util import tf_tree
from replay.util.errors import DataError

from .. import rosmsg
from ..mapping import pose_like
from .recording import Recording


def key(entry) -> tuple:
    """Entries reading the same messages share one source: (topic, parent, child)."""
    return entry.topic, entry.frame, entry.child


def _pairs_text(seen: dict) -> str:
    items = sorted(seen.items(), key=lambda kv: -kv[1])
    text = ", ".join(f"{p} -> {c} ({n})" for (p, c), n in items[:8])
    return text + (f", ... ({len(items) - 8} more)" if len(items) > 8 else "") if items else "none"


def messages(rec: Recording, entry) -> tuple[list, list, str]:
    """(messages, their log times, converter kind) of ``entry``; one line naming file and topic
    when a TF pair is missing or not named, or a Path is empty."""
    topic = rec.topics[entry.topic]
    kind = rosmsg.kind_of(topic.type)
    where = f"topic {entry.topic} (mapped to {entry.name})"
    if kind == "tf":
        many = topic.type.endswith("TFMessage")
        _, _, seen = rosmsg.tf_pair(topic.msgs, topic.log_ns, None, None)
        if many and entry.frame is None:
            raise DataError(
                rec.path,
                f"{where} is a {topic.type}, which holds several transforms: name the "
                f"pair with frame = \"parent\" and child = \"child\" in the entry "
                f"(pairs: {_pairs_text(seen)})",
            )
        msgs, logs, _ = rosmsg.tf_pair(topic.msgs, topic.log_ns, entry.frame, entry.child)
        if not msgs and many:  # not recorded as one pair: composed through the tree (map -> odom -> base_link)
            msgs, logs = composed(rec, entry, where, seen)
        if not msgs:
            raise DataError(
                rec.path, f"{where}: no transform {entry.frame} -> {entry.child} (pairs: {_pairs_text(seen)})"
            )
        return msgs, logs, "pose"
    if entry.frame is not None:
        raise DataError(rec.path, f"{where}: frame/child select a TF pair, but the topic is a {topic.type}")
    if kind == "path":
        msgs, logs = rosmsg.path_poses(topic.msgs, topic.log_ns)
        if not msgs:
            raise DataError(rec.path, f"{where}: its last nav_msgs/Path message holds no pose")
        return msgs, logs, "pose"
    return topic.msgs, topic.log_ns, pose_like(kind)


def composed(rec: Recording, entry, where: str, seen) -> tuple[list, list]:
    """The poses ``entry.frame -> entry.child`` composed through the recording's TF tree (every
    TFMessage topic read, ``/tf_static`` among them when mapped) at the stamps of its most frequent
    dynamic edge (:func:`replay.util.tf_tree.compose`, as ``replay score BAG:tf:PARENT->CHILD``);
    their "log times" are those stamps. ([], []) when the frames are not joined."""
    tf_topics = [name for name, t in rec.topics.items() if t.type.endswith("TFMessage")]
    edges = tf_tree.tf_edges(rec, tf_topics)
    steps = tf_tree.path_between(edges, rosmsg.frame_name(entry.frame), rosmsg.frame_name(entry.child))
    if not steps:
        return [], []
    try:
        times, p, q = tf_tree.compose(edges, steps)
    except ValueError as err:
        raise DataError(rec.path, f"{where}: {entry.frame} -> {entry.child}: {err}") from None
    ns = np.round(times * 1e9).astype(np.int64)
    head = [
        rosmsg._Plain(
            stamp=rosmsg._Plain(sec=int(t // 1_000_000_000), nanosec=int(t % 1_000_000_000)), frame_id=entry.frame
        )
        for t in ns
    ]
    poses = [
        rosmsg._Pose(h, rosmsg._Plain(x=a[0], y=a[1], z=a[2]), rosmsg._Plain(x=b[0], y=b[1], z=b[2], w=b[3]))
        for h, a, b in zip(head, p.tolist(), q.tolist())
    ]
    return poses, list(ns)


def stamps(rec: Recording, entry, msgs: list, log_ns, time: str) -> tuple[np.ndarray, np.ndarray]:
    """(the stamps used, the other time) in ns; non-increasing stamps -> one line naming file and topic.

    A Path's poses always use their own header stamps (its messages have one log time).
    """
    log = np.asarray(log_ns, np.int64)
    header = np.array([rosmsg.stamp_ns(m) for m in msgs], np.int64)
    if rosmsg.kind_of(rec.topics[entry.topic].type) == "path":
        time = "header"
    use = header if time == "header" else log
    d = np.diff(use)
    bad = np.flatnonzero(d <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        what = f"{entry.topic}{entry.pair}" if entry.frame else entry.topic
        if d[bad[0]] == 0:
            raise DataError(
                rec.path,
                f"topic {what}: non-increasing {time} stamps at message {i} (duplicate stamp: {use[i]} ns twice)",
            )
        raise DataError(
            rec.path, f"topic {what}: non-increasing {time} stamps at message {i} ({use[i]} ns after {use[i - 1]} ns)"
        )
    return use, (log if time == "header" else header)
