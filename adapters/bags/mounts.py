"""Sensor mountings from the recording's ``/tf_static`` (issue 34 item 1), as robot_localization
reads them: the static transform from the body frame to a sensor's message frame
(``base_link -> imu_link``, ``base_link -> gps_link``).

The body frame is the ``child_frame_id`` of the first mapped Odometry entry (REP 105), else
``base_link``. For every input whose role has a mounting (``Role.mount``: an IMU's rotation, a
GPS antenna's lever arm) and whose messages name a frame other than the body's, the static path
between the two (through any chain of ``/tf_static`` edges) becomes the input's
``recorded_mount`` (:class:`replay.roles.Mount`), and a report line says it; the task applies
it unless the mapping declares the mount (``mount``, ``lever_arm``: declared wins, the task
notes a conflict). Only ``/tf_static`` is read (it is small and latched); ``/tf`` is not.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from replay.roles import Mount
from replay.util import tf_tree

from .. import rosmsg
from .sources import key

STATIC = "/tf_static"
BODY = "base_link"


def with_static(topics):
    """The topics to read (a list, or a function of the listing ``{topic: (type, count)}``) and the
    recording's ``/tf_static`` beside them when it has one."""

    def chosen(listing):
        names = list(topics(listing) if callable(topics) else topics)
        return names + [STATIC] if STATIC in listing and STATIC not in names else names

    return chosen


def frames_of(msgs) -> tuple[str, str]:
    """(header.frame_id, child_frame_id) of a topic's first message ('' where it has none)."""
    if not msgs or not hasattr(msgs[0], "header"):
        return "", ""
    return str(msgs[0].header.frame_id).strip("/"), str(getattr(msgs[0], "child_frame_id", "") or "").strip("/")


def attach(rec, mp, inputs, frames: dict, kinds: dict, report) -> tuple:
    """``inputs`` with the recorded mounting of each that has one (``frames``/``kinds``: per source
    key, see :func:`frames_of`); report lines for what was found and for a sensor frame that
    ``/tf_static`` does not join to the body."""
    topic = rec.topics.get(STATIC)
    if topic is None or not topic.msgs:
        return tuple(inputs)
    edges = tf_tree.tf_edges(rec, [STATIC])
    by_entry = {e.name: key(e) for e in mp.entries if not e.reference}
    odom = [by_entry[i.entry] for i in inputs if kinds.get(by_entry[i.entry]) == "odometry"]
    body = next((frames[s][1] for s in odom if frames[s][1]), BODY)
    out = []
    for inp in inputs:
        sensor = frames.get(by_entry[inp.entry], ("", ""))[0]
        if inp.spec.mount is None or not sensor or sensor == body:
            out.append(inp)
            continue
        found = tf_tree.static_between(edges, body, sensor)
        if found is None:
            report.add(
                "info",
                inp.entry,
                0,
                f"{STATIC}: no static transform {body} -> {sensor}: its mounting is not recorded "
                "(declare mount / lever_arm in the mapping if its axes are not the body's)",
            )
            out.append(inp)
            continue
        p, q = found
        rpy = rosmsg.quat_to_rpy(np.asarray(q, float)[None])[0]
        clean = lambda v: tuple(float(x) for x in np.round(v, 12) + 0.0)  # no -0.0, no 1e-17 for a zero
        mount = Mount(clean(rpy), clean(p), body, sensor)
        report.add("info", inp.entry, 1, f"{STATIC}: mounting {describe(mount)}")
        out.append(dataclasses.replace(inp, recorded_mount=mount))
    return tuple(out)


def describe(m: Mount) -> str:
    rot = ", ".join(f"{v:.6g}" for v in m.rotation)
    arm = ", ".join(f"{v:.6g}" for v in m.translation)
    return f"{m.parent} -> {m.child}: rotation [{rot}] rad (roll, pitch, yaw), translation [{arm}] m"
