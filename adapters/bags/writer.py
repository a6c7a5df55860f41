"""Writing ROS 2 bags (MCAP storage, the humble typestore): the inverse of :func:`.load`.

Used by the exports (:mod:`replay.outputs.export_ros2`) and by the simulated
bag dataset; no Foxglove JSON/protobuf channel ever goes into these bags.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from replay.util.errors import ReplayError


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


class BagOut:
    """rosbags' ROS 2 writer with MCAP storage; messages built from the humble typestore."""

    def __init__(self, path, overwrite: bool = True):
        from rosbags.rosbag2 import StoragePlugin, Writer

        path = Path(path)
        if path.exists():
            if not overwrite or not (path / "metadata.yaml").is_file():
                raise ReplayError(f"{path}: exists and is not a ROS 2 bag to replace")
            shutil.rmtree(path)
        self.ts = _typestore()
        self.T = self.ts.types
        self.w = Writer(path, version=8, storage_plugin=StoragePlugin.MCAP)
        self.w.open()
        self.count = 0

    def connection(self, topic, msgtype):
        return self.w.add_connection(topic, msgtype, typestore=self.ts)

    def write(self, conn, log_ns: int, msg) -> None:
        self.w.write(conn, int(log_ns), self.ts.serialize_cdr(msg, conn.msgtype))
        self.count += 1

    def close(self):
        self.w.close()

    # message pieces
    def header(self, ns: int, frame_id: str):
        sec, nsec = divmod(int(ns), 1_000_000_000)
        return self.T["std_msgs/msg/Header"](stamp=self.T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                             frame_id=frame_id)

    def vec(self, v):
        return self.T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def point(self, v):
        return self.T["geometry_msgs/msg/Point"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quat(self, q):
        return self.T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def pose(self, p, q):
        return self.T["geometry_msgs/msg/Pose"](position=self.point(p), orientation=self.quat(q))

    def twist(self, v, w):
        return self.T["geometry_msgs/msg/Twist"](linear=self.vec(v), angular=self.vec(w))

    def odometry(self, ns, frame_id, child, p, q, v, w, pcov=None):
        T = self.T
        pcov = np.zeros(36) if pcov is None else np.asarray(pcov, float)
        return T["nav_msgs/msg/Odometry"](
            header=self.header(ns, frame_id), child_frame_id=child,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(p, q), covariance=pcov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=self.twist(v, w), covariance=np.zeros(36)))
