"""The transform tree of a recording (``/tf``, ``/tf_static``): edges, the path between two frames,
their composition over time — shared by ``replay score BAG:tf:PARENT->CHILD``
(:mod:`replay.trajectory.bag`) and the bag adapter's TF estimates, which need not be recorded
as one pair (``map -> odom -> base_link``).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from replay.util import quat


def seconds(stamp) -> float:
    """A ROS stamp in seconds, as evo reads it."""
    return stamp.sec + stamp.nanosec * 1e-9


def xyz(v) -> tuple:
    return (v.x, v.y, v.z)


def xyzw(q) -> tuple:
    return (q.x, q.y, q.z, q.w)


def tf_edges(rec, topics) -> dict:
    """{(parent, child): (t, p, q, static)} of every transform recorded on ``topics`` of ``rec``
    (a recording read by the bag adapter: ``rec.topics[name].type``, ``.msgs``)."""
    raw = {}
    for topic in rec.topics.values():
        if topic.name not in topics or topic.type != "tf2_msgs/msg/TFMessage":
            continue
        static = topic.name.lstrip("/") == "tf_static"
        for m in topic.msgs:
            for tr in m.transforms:
                key = (str(tr.header.frame_id).lstrip("/"), str(tr.child_frame_id).lstrip("/"))
                e = raw.setdefault(key, ([], [], [], static))
                e[0].append(seconds(tr.header.stamp))
                e[1].append(xyz(tr.transform.translation))
                e[2].append(xyzw(tr.transform.rotation))
    out = {}
    for key, (t, p, q, static) in raw.items():
        t, p, q = np.array(t), np.array(p, float), quat.normalize(np.array(q, float))
        order = np.argsort(t, kind="stable")
        t, p, q = t[order], p[order], q[order]
        keep = np.concatenate([np.diff(t) > 0, [True]])  # a repeated stamp: the last one sent
        out[key] = (t[keep], p[keep], q[keep], static)
    return out


def path_between(edges, parent: str, child: str):
    """[(edge key, forward)] from parent to child through the undirected tree, or None."""
    nbr = {}
    for a, b in edges:
        nbr.setdefault(a, []).append((b, (a, b), True))
        nbr.setdefault(b, []).append((a, (a, b), False))
    prev, todo = {parent: None}, deque([parent])
    while todo:
        f = todo.popleft()
        for g, key, fwd in nbr.get(f, []):
            if g not in prev:
                prev[g] = (f, key, fwd)
                todo.append(g)
    if child not in prev:
        return None
    steps, f = [], child
    while prev[f] is not None:
        f, key, fwd = prev[f]
        steps.append((key, fwd))
    return steps[::-1]


def at(edge, times):
    """Edge transform (p, q) at ``times`` (interpolated; static edges: their one value)."""
    t, p, q, static = edge
    if static or len(t) == 1:
        return np.repeat(p[-1:], len(times), 0), np.repeat(q[-1:], len(times), 0)
    k = np.clip(np.searchsorted(t, times, side="right"), 1, len(t) - 1)
    f = (times - t[k - 1]) / (t[k] - t[k - 1])
    return p[k - 1] + f[:, None] * (p[k] - p[k - 1]), quat.slerp(q[k - 1], q[k], f)


def compose(edges, steps):
    """(times, p, q) of the transform along ``steps`` (:func:`path_between`): the stamps of the most
    frequent dynamic edge, within every dynamic edge's span (tf does not extrapolate), each edge
    interpolated there (:func:`at`) and inverted where walked backwards. ValueError when only
    static edges join the frames (a constant pose, not a trajectory)."""
    dynamic = [key for key, _ in steps if not edges[key][3] and len(edges[key][0]) > 1]
    if not dynamic:
        raise ValueError("only static transforms join these frames: a constant pose, not a trajectory")
    lead = max(dynamic, key=lambda key: len(edges[key][0]))
    times = edges[lead][0]
    for key in dynamic:
        t = edges[key][0]
        times = times[(times >= t[0]) & (times <= t[-1])]
    p, q = np.zeros((len(times), 3)), np.tile([0.0, 0.0, 0.0, 1.0], (len(times), 1))
    for key, fwd in steps:
        ep, eq = at(edges[key], times)
        if not fwd:  # inverse: (R', -R' p)
            eq = quat.conjugate(eq)
            ep = -quat.rotate(eq, ep)
        p, q = p + quat.rotate(q, ep), quat.multiply(q, eq)
    return times, p, q


def static_between(edges, parent: str, child: str):
    """(p, q) of the constant transform parent -> child through static edges only (``/tf_static``:
    a sensor's mounting, e.g. ``base_link -> imu_link``), or None when no static path joins them."""
    static = {key: e for key, e in edges.items() if e[3]}
    steps = path_between(static, parent, child)
    if steps is None:
        return None
    p, q = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])
    for key, fwd in steps:
        ep, eq = static[key][1][-1], static[key][2][-1]
        if not fwd:  # inverse: (R', -R' p)
            eq = quat.conjugate(eq)
            ep = -quat.rotate(eq, ep)
        p, q = p + quat.rotate(q, ep), quat.multiply(q, eq)
    return p, q
