"""Record the detector's output: ``/uav/pose`` into a ``timestamp,x,y,z`` CSV for the
evaluator, optionally ``/uav/points`` (drone points, for plots) and a ROS 2 bag.

:class:`PoseRecorder` works on any rclpy node, so tests record in-process through the
same code as the ``clusterfilter record`` command.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import PointCloud2

from clusterfilter_ros.core.frame import TimedPositions
from clusterfilter_ros.io.groundtruth import write_positions_csv
from clusterfilter_ros.io.pointcloud2 import decode_pointcloud2
from clusterfilter_ros.ros.stamps import time_msg_to_seconds

POSE_TOPIC = "/uav/pose"
POINTS_TOPIC = "/uav/points"
DIAGNOSTICS_TOPIC = "/diagnostics"

#: Recorder subscriptions: reliable, keep last 500 (poses are small; none should be lost,
#: and /uav/pose_delayed publishes up to a few hundred at once at a confirmation).
RECORD_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=500,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


class PoseRecorder:
    """Collect ``PoseStamped`` messages (and optionally drone clouds) on ``node``.

    Args:
        node: any rclpy node; its executor must spin for messages to arrive.
        pose_topic: PoseStamped topic to record.
        points_topic: PointCloud2 topic of drone points to collect too (None: not).
        keep_messages: keep the serialized messages for :meth:`write_bag`.
        watch_diagnostics: follow the detector's ``/diagnostics`` to know how many
            frames it has handled (:meth:`frames_handled`).
    """

    def __init__(
        self,
        node: Node,
        pose_topic: str = POSE_TOPIC,
        points_topic: str | None = None,
        keep_messages: bool = False,
        watch_diagnostics: bool = False,
    ) -> None:
        self.node = node
        self.pose_topic = pose_topic
        self.points_topic = points_topic
        self._lock = threading.Lock()
        self._stamps: list[float] = []
        self._xyz: list[tuple[float, float, float]] = []
        self._points: list[np.ndarray] = []
        self._raw: list[tuple[str, str, int, bytes]] = []  # topic, type, stamp ns, cdr
        self._keep = keep_messages
        self.first_receipt: float | None = None
        self.last_receipt: float | None = None
        self.rejected_points = 0
        self._handled: tuple[int, int] | None = None
        self._subs = [node.create_subscription(PoseStamped, pose_topic, self._on_pose, RECORD_QOS)]
        if points_topic:
            self._subs.append(
                node.create_subscription(PointCloud2, points_topic, self._on_points, RECORD_QOS)
            )
        if watch_diagnostics:
            self._subs.append(
                node.create_subscription(
                    DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diagnostics, RECORD_QOS
                )
            )

    def _on_pose(self, msg: PoseStamped) -> None:
        now = time.monotonic()
        p = msg.pose.position
        with self._lock:
            self._stamps.append(time_msg_to_seconds(msg.header.stamp))
            self._xyz.append((p.x, p.y, p.z))
            if self.first_receipt is None:
                self.first_receipt = now
            self.last_receipt = now
            if self._keep:
                self._raw.append(
                    (
                        self.pose_topic,
                        "geometry_msgs/msg/PoseStamped",
                        _ns(msg),
                        serialize_message(msg),
                    )
                )

    def _on_points(self, msg: PointCloud2) -> None:
        try:
            xyz = decode_pointcloud2(msg, "drone").frame.xyz
        except Exception:  # a malformed debug cloud is skipped, never fatal
            with self._lock:
                self.rejected_points += 1
            return
        with self._lock:
            self._points.append(xyz)
            if self._keep:
                self._raw.append(
                    (
                        self.points_topic,
                        "sensor_msgs/msg/PointCloud2",
                        _ns(msg),
                        serialize_message(msg),
                    )
                )

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        handled, queued, found = 0, 0, False
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            try:
                if "frames_processed" in values:
                    found = True
                    handled += int(values["frames_processed"]) + int(values["dropped_late"])
                    handled += int(values["dropped_queue_full"])
                    handled += int(values.get("detector_errors", "0"))
                    queued += int(values["frames_queued"])
                if "rejected_malformed" in values:
                    handled += int(values["rejected_malformed"])
            except (KeyError, ValueError):
                return  # not the detector's diagnostics
        if found:
            with self._lock:
                self._handled = (handled, queued)

    def frames_handled(self) -> tuple[int, int] | None:
        """From the detector's last ``/diagnostics``: (input frames handled so far, i.e.
        processed, failed, dropped or rejected; frames still queued); None before the
        first message."""
        with self._lock:
            return self._handled

    def __len__(self) -> int:
        with self._lock:
            return len(self._stamps)

    def positions(self) -> TimedPositions:
        """The recorded poses, sorted by stamp."""
        with self._lock:
            return TimedPositions(np.array(self._stamps, dtype=np.float64), np.array(self._xyz))

    def drone_points(self) -> np.ndarray:
        """Every recorded drone point stacked, (M, 3) float32."""
        with self._lock:
            if not self._points:
                return np.empty((0, 3), dtype=np.float32)
            return np.concatenate(self._points, axis=0)

    def matched_publishers(self) -> int:
        """Publishers of the pose topic this recorder is matched with right now."""
        return self._subs[0].get_publisher_count()

    def idle_for(self, now: float | None = None) -> float | None:
        """Seconds since the last pose (None before the first one)."""
        if self.last_receipt is None:
            return None
        return (time.monotonic() if now is None else now) - self.last_receipt

    def write_csv(self, path: str | os.PathLike[str]) -> Path:
        """Write ``timestamp,x,y,z`` atomically; returns the path."""
        return write_positions_csv(path, self.positions())

    def write_points(self, path: str | os.PathLike[str]) -> Path:
        """Write the drone points as an (M, 3) float32 ``.npy`` atomically."""
        from clusterfilter_ros.io.atomic import atomic_output_path

        with atomic_output_path(path, suffix=".npy") as tmp:
            np.save(tmp, self.drone_points())
        return Path(path)

    def write_bag(self, path: str | os.PathLike[str]) -> Path:
        """Write the recorded messages as a ROS 2 bag (sqlite3) at ``path``.

        Needs ``keep_messages=True``. rosbags writes the CDR bytes rclpy produced.
        """
        if not self._keep:
            raise ValueError("PoseRecorder was created without keep_messages=True")
        from rosbags.rosbag2 import Writer
        from rosbags.typesys import Stores, get_typestore

        from clusterfilter_ros.errors import InputError

        target = Path(path)
        if target.exists():
            raise InputError(f"{target} already exists; choose a new bag folder")
        typestore = get_typestore(Stores.ROS2_JAZZY)
        with self._lock:
            raw = sorted(self._raw, key=lambda r: r[2])
        with Writer(target, version=9) as writer:
            connections = {}
            for topic, msgtype in dict.fromkeys((t, m) for t, m, _, _ in raw) or [
                (self.pose_topic, "geometry_msgs/msg/PoseStamped")
            ]:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=typestore)
            for topic, _, stamp_ns, data in raw:
                writer.write(connections[topic], stamp_ns, data)
        return target

    def destroy(self) -> None:
        """Destroy the subscriptions (the node stays)."""
        for sub in self._subs:
            self.node.destroy_subscription(sub)


def _ns(msg: PoseStamped | PointCloud2) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
