"""Trajectories recorded in ROS bags and MCAP files (read by :mod:`replay.adapters.bags`).

``read_topic(path, topic)`` by message type, stamps from ``header.stamp`` (seconds as
``sec + nanosec * 1e-9``, as evo reads them):

| type | poses | covariance |
|---|---|---|
| nav_msgs/Odometry | ``pose.pose`` | ``pose.covariance`` (6x6) |
| geometry_msgs/PoseStamped | ``pose`` | |
| geometry_msgs/PoseWithCovarianceStamped | ``pose.pose`` | ``pose.covariance`` (6x6) |
| geometry_msgs/TransformStamped | ``transform`` | |
| nav_msgs/Path | the poses of the **last** message (each with its own stamp) | |
| sensor_msgs/NavSatFix | local ENU (m) of the fixes, through the UTM zone of the first fix (no orientation; NO_FIX and 0/0 fixes dropped) | ``position_covariance`` (3x3, ENU) |

``read_tf(path, parent, child)``: the transform parent -> child from ``/tf`` and
``/tf_static`` (``tf_static`` and names without the leading slash too). The frames are
joined through the tree of recorded edges (each edge used forward or inverted). The
stamps are those of the most frequent dynamic edge on the path; every other dynamic
edge is interpolated there (linear in position, slerp in orientation), and stamps
outside its recorded span are dropped, as tf does not extrapolate. A path of static
edges only is a constant transform, not a trajectory, and is refused.
"""  # noqa: E501 (Markdown tables)

from __future__ import annotations

from pathlib import Path

import numpy as np

from replay.trajectory import stamps
from replay.trajectory.base import Trajectory, make
from replay.util.errors import DataError
from replay.util.tf_tree import compose, path_between, tf_edges
from replay.util.tf_tree import seconds as _seconds, xyz as _xyz, xyzw as _xyzw
from replay.adapters.geodesy import Geo

POSE_TYPES = (
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/TransformStamped",
    "nav_msgs/msg/Path",
    "sensor_msgs/msg/NavSatFix",
)
TF_TOPICS = ("/tf", "tf", "/tf_static", "tf_static")


def read_recording(path, topics):
    """The recording at ``path`` with the messages of ``topics`` (one pass for several trajectories)."""
    return _read(Path(path), topics)


def _read(path: Path, topics):
    # lazy: start-up, the bags package measured ~120-200 ms on `import replay.trajectory`
    from replay.adapters.bags import read  # noqa: PLC0415

    rec = read(path, topics=topics)
    if rec.truncated:
        raise DataError(path, f"truncated or corrupted: {rec.truncated}")
    return rec


def _find(rec, topic: str):
    if topic in rec.topics:
        return rec.topics[topic]
    alt = topic[1:] if topic.startswith("/") else "/" + topic
    return rec.topics.get(alt)


def topics_of(topic: str) -> list:
    """The topic names to read for ``topic`` (with and without the leading slash; tf: both tf topics)."""
    if topic.startswith(("tf:", "/tf:")):
        return list(TF_TOPICS)
    return [topic, topic[1:] if topic.startswith("/") else "/" + topic]


def read_topic(path, topic: str, *, name: str = "", rec=None) -> Trajectory:
    """The trajectory recorded on ``topic`` (module docstring); ``rec``: the recording already read
    (:func:`replay.adapters.bags.read` with :func:`topics_of` among its topics)."""
    path = Path(path)
    rec = rec if rec is not None else _read(path, topics_of(topic))
    src = f"{path}:{topic}"
    top = _find(rec, topic)
    if top is None:
        listed = (
            ", ".join(f"{t.name} ({t.type.split('/')[-1]})" for t in rec.topics.values() if t.type in POSE_TYPES)
            or "none"
        )
        raise DataError(path, f"no topic {topic!r} (trajectory topics: {listed})")
    if top.type == "tf2_msgs/msg/TFMessage":
        raise DataError(src, "a tf topic: name the frames as BAG:tf:PARENT->CHILD")
    if top.type not in POSE_TYPES:
        raise DataError(
            src,
            f"message type {top.type} is not a trajectory (supported: "
            f"{', '.join(t.split('/')[-1] for t in POSE_TYPES)}, and tf frames as tf:PARENT->CHILD)",
        )
    msgs = top.msgs
    if not msgs:
        raise DataError(src, "no messages")
    name = name or topic
    kind = top.type
    cov = None
    if kind == "nav_msgs/msg/Path":
        poses = msgs[-1].poses
        if not poses:
            raise DataError(src, f"the last of the {len(msgs)} Path messages holds no poses")
        t = [_seconds(ps.header.stamp) for ps in poses]
        p = [_xyz(ps.pose.position) for ps in poses]
        q = [_xyzw(ps.pose.orientation) for ps in poses]
        ns = stamps.of_header(ps.header.stamp for ps in poses)
        return make(t, p, q, source=f"{src} (last Path message)", name=name, rows=np.arange(len(t)), unit="pose", ns=ns)
    t = [_seconds(m.header.stamp) for m in msgs]
    if kind == "sensor_msgs/msg/NavSatFix":
        return _fixes(src, msgs, np.array(t), name, stamps.of_header(m.header.stamp for m in msgs))
    if kind == "geometry_msgs/msg/TransformStamped":
        p = [_xyz(m.transform.translation) for m in msgs]
        q = [_xyzw(m.transform.rotation) for m in msgs]
    else:
        poses = [m.pose.pose if hasattr(m.pose, "pose") else m.pose for m in msgs]
        p = [_xyz(ps.position) for ps in poses]
        q = [_xyzw(ps.orientation) for ps in poses]
        if hasattr(msgs[0].pose, "covariance"):
            cov = np.array([np.asarray(m.pose.covariance, float) for m in msgs]).reshape(-1, 6, 6)
            if not cov.any():
                cov = None  # all zeros: no covariance recorded
    ns = stamps.of_header(m.header.stamp for m in msgs)
    return make(t, p, q, cov, source=src, name=name, rows=np.arange(len(t)), unit="message", ns=ns)


def _fixes(src: str, msgs, t: np.ndarray, name: str, ns: np.ndarray) -> Trajectory:
    lat = np.array([m.latitude for m in msgs], float)
    lon = np.array([m.longitude for m in msgs], float)
    alt = np.array([m.altitude for m in msgs], float)
    status = np.array([m.status.status for m in msgs], float)
    ok = (status >= 0) & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(alt)
    ok &= (np.abs(lat) <= 90) & (np.abs(lon) <= 180) & ~((lat == 0) & (lon == 0))
    if not ok.any():
        raise DataError(src, f"none of the {len(msgs)} fixes is valid (status NO_FIX or impossible coordinates)")
    enu = Geo(lat, lon, alt, ok).forward(lat, lon, alt, ok)
    cov = np.array([np.asarray(m.position_covariance, float) for m in msgs]).reshape(-1, 3, 3)
    idx = np.flatnonzero(ok)
    return make(
        t[idx],
        enu[idx],
        None,
        cov[idx] if cov[idx].any() else None,
        source=src,
        name=name,
        rows=idx,
        unit="message",
        ns=ns[idx],
    )


def parse_tf(spec: str):
    """``PARENT->CHILD``, or the spellings that need no shell quoting: ``PARENT,CHILD``, ``PARENT:CHILD``
    and evo's ``PARENT.CHILD`` -> (parent, child)."""
    if spec.endswith("-") and "->" not in spec:  # an unquoted A->B: the shell redirected stdout to a file B
        raise DataError(
            f"tf:{spec}",
            "the shell took '>' for a redirection (and wrote a file named after the child "
            "frame): quote the argument ('REC:tf:map->base_link') or write REC:tf:map,base_link",
        )
    for sep in ("->", ",", ":", "."):
        if sep in spec:
            parent, child = spec.split(sep, 1)
            break
    else:
        parent, child = spec, ""
    parent, child = parent.strip().lstrip("/"), child.strip().lstrip("/")
    if not parent or not child:
        raise DataError(
            f"tf:{spec}",
            "expected tf:PARENT->CHILD (quoted), tf:PARENT,CHILD or tf:PARENT.CHILD, e.g. tf:map,base_link",
        )
    return parent, child


def read_tf(path, parent: str, child: str, *, name: str = "", rec=None) -> Trajectory:
    """The transform ``parent -> child`` over time (module docstring)."""
    path = Path(path)
    rec = rec if rec is not None else _read(path, list(TF_TOPICS))
    src = f"{path}:tf:{parent}->{child}"
    edges = tf_edges(rec, TF_TOPICS)
    if not edges:
        raise DataError(path, "no tf messages (/tf, /tf_static)")
    steps = path_between(edges, parent, child)
    if steps is None:
        frames = sorted({f for key in edges for f in key})
        missing = [f for f in (parent, child) if f not in frames]
        what = f"frame {missing[0]!r} is not in the tf tree" if missing else "the frames are not connected"
        raise DataError(src, f"{what} (frames: {', '.join(frames[:30])}{' ...' if len(frames) > 30 else ''})")
    try:
        times, p, q = compose(edges, steps)
    except ValueError as err:
        raise DataError(src, str(err)) from None
    return make(times, p, q, source=src, name=name or f"tf:{parent}->{child}", unit="stamp")
