"""Writing ROS 2 bags (MCAP storage, the humble typestore): the inverse of :func:`.load`.

Used by the exports (:mod:`replay.outputs.export_ros2`) and by the simulated
bag dataset; no Foxglove JSON/protobuf channel ever goes into these bags.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from replay.util.errors import ReplayError


def _typestore():
    # lazy: start-up, every adapter imports the bags package and so this module: rosbags.rosbag2 measured ~190 ms
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415

    return get_typestore(Stores.ROS2_HUMBLE)


class BagOut:
    """rosbags' ROS 2 writer with MCAP storage; messages built from the humble typestore.

    ``path`` must not exist: nothing is ever replaced here (an export writes into a
    hidden temporary directory and swaps it in, ``replay.outputs.export_safety``).
    ``custom_data`` (str -> str) goes into ``metadata.yaml`` (rosbag2 ``custom_data``).
    ``compression="zstd"``: the MCAP chunks are zstd-compressed, as ``ros2 bag record -s mcap``
    writes them (the storage's own compression: ``metadata.yaml`` keeps an empty
    ``compression_format``/``compression_mode``, any MCAP reader opens the file); ``None``:
    uncompressed chunks.
    """

    def __init__(self, path, custom_data: dict | None = None, compression: str | None = None):
        # lazy: start-up, every adapter imports the bags package and so this module: rosbags.rosbag2 measured ~190 ms
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer  # noqa: PLC0415
        from rosbags.rosbag2.errors import WriterError  # noqa: PLC0415

        if compression not in (None, "zstd"):
            raise ValueError(f"compression {compression!r}: zstd or None")
        path = Path(path)
        if path.exists() or path.is_symlink():
            raise ReplayError(f"{path}: exists; a ROS 2 bag is written to a new directory only")
        self.path = path
        self.ts = _typestore()
        self.T = self.ts.types
        try:
            self.w = Writer(path, version=8, storage_plugin=StoragePlugin.MCAP)
            if compression:
                self.w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            for key, value in (custom_data or {}).items():
                self.w.set_custom_data(key, value)
            self.w.open()
        except (WriterError, OSError) as e:
            raise ReplayError(f"{path}: cannot write a ROS 2 bag: {e}") from None
        self.count = 0

    def connection(self, topic, msgtype):
        return self.w.add_connection(topic, msgtype, typestore=self.ts)

    def write(self, conn, log_ns: int, msg) -> None:
        self.w.write(conn, int(log_ns), self.ts.serialize_cdr(msg, conn.msgtype))
        self.count += 1

    def close(self):
        """Write the summary and metadata.yaml (the bag is complete only then)."""
        if self.w.storage is not None:
            self.w.close()

    # message pieces
    def header(self, ns: int, frame_id: str):
        sec, nsec = divmod(int(ns), 1_000_000_000)
        return self.T["std_msgs/msg/Header"](
            stamp=self.T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame_id
        )

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
            header=self.header(ns, frame_id),
            child_frame_id=child,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(p, q), covariance=pcov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=self.twist(v, w), covariance=np.zeros(36)),
        )
