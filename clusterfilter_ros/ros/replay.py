"""Publish a recording (challenge folder or bag) on the detector's topics, paced by stamps.

Lidar frames go out as livox_ros_driver2-layout ``sensor_msgs/PointCloud2`` on the two
lidar topics, ground truth as ``geometry_msgs/PointStamped`` on ``/uav/ground_truth``,
all in stamp order (ties: sensor name) with the original header stamps. With ``rate``
R > 0 the wall-clock gap between two messages is their stamp gap divided by R; with
``rate`` 0 messages go out back to back, still in order.

:class:`Replayer` works on any rclpy node, so tests drive a detector node in-process
through the same code the ``clusterfilter replay`` command uses.
"""

from __future__ import annotations

import heapq
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

from clusterfilter_ros.core.frame import AVIA, MID360, Frame, Sequence, TimedPositions
from clusterfilter_ros.io.pointcloud2 import make_pointcloud2
from clusterfilter_ros.ros.stamps import seconds_to_time_msg

GROUND_TRUTH_TOPIC = "/uav/ground_truth"

#: Replay publishers: reliable (matches best-effort and reliable subscribers), keep last 10.
REPLAY_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


@dataclass
class ReplayStats:
    """What one :meth:`Replayer.play` published."""

    frames: dict[str, int] = field(default_factory=dict)
    ground_truth: int = 0
    wall_seconds: float = 0.0
    stamp_seconds: float = 0.0
    max_behind_seconds: float = 0.0  # how late (wall clock) the worst message went out
    stopped: bool = False

    @property
    def total_frames(self) -> int:
        return sum(self.frames.values())


class Replayer:
    """Publishers for one replay on ``node``.

    Args:
        node: any rclpy node (its context decides the DDS domain).
        topics: sensor name -> PointCloud2 topic (default avia/mid360 on ``/livox/...``).
        ground_truth_topic: PointStamped topic for ground truth (None: not published).
        frame_ids: sensor name -> header frame_id of its clouds (default: the sensor name).
        ground_truth_frame_id: header frame_id of the ground truth points.
    """

    def __init__(
        self,
        node: Node,
        topics: dict[str, str] | None = None,
        ground_truth_topic: str | None = GROUND_TRUTH_TOPIC,
        frame_ids: dict[str, str] | None = None,
        ground_truth_frame_id: str = "map",
    ) -> None:
        self.node = node
        self.topics = dict(topics or {AVIA: "/livox/avia", MID360: "/livox/mid360"})
        self.frame_ids = dict(frame_ids or {})
        self.ground_truth_frame_id = ground_truth_frame_id
        self.publishers = {
            sensor: node.create_publisher(PointCloud2, topic, REPLAY_QOS)
            for sensor, topic in self.topics.items()
        }
        self.ground_truth_publisher = (
            node.create_publisher(PointStamped, ground_truth_topic, REPLAY_QOS)
            if ground_truth_topic
            else None
        )

    def wait_for_subscribers(
        self,
        timeout: float,
        extra_topics: Iterable[str] = (),
        settle: float = 0.5,
        stop: threading.Event | None = None,
    ) -> bool:
        """Wait until every lidar topic has a matched subscriber and every topic in
        ``extra_topics`` has a subscriber in the graph, then ``settle`` seconds more
        (best-effort readers may lag the writer's view of the match). False on timeout.
        """
        extra = list(extra_topics)
        deadline = time.monotonic() + timeout
        while True:
            ready = all(p.get_subscription_count() > 0 for p in self.publishers.values()) and all(
                self.node.count_subscribers(t) > 0 for t in extra
            )
            if ready:
                break
            if time.monotonic() > deadline or (stop is not None and stop.is_set()):
                return False
            time.sleep(0.05)
        time.sleep(settle)
        return True

    def missing_subscribers(self, extra_topics: Iterable[str] = ()) -> list[str]:
        """Topics that have no subscriber right now (for error messages)."""
        missing = [
            self.topics[s] for s, p in self.publishers.items() if p.get_subscription_count() == 0
        ]
        return missing + [t for t in extra_topics if self.node.count_subscribers(t) == 0]

    def play(
        self,
        frames: Iterable[Frame],
        ground_truth: TimedPositions | None = None,
        rate: float = 1.0,
        stop: threading.Event | None = None,
        on_frame: Callable[[Frame], None] | None = None,
    ) -> ReplayStats:
        """Publish ``frames`` (time-ordered) and ``ground_truth``, paced by their stamps.

        Frames of sensors without a topic are skipped. ``stop`` ends the replay early;
        ``on_frame`` is called after each frame is published.
        """
        if rate < 0:
            raise ValueError(f"rate must be >= 0, got {rate}")
        stats = ReplayStats()
        started = time.monotonic()
        first_stamp: float | None = None
        last_stamp = 0.0
        for kind, stamp, payload in _merged_items(frames, ground_truth):
            if stop is not None and stop.is_set():
                stats.stopped = True
                break
            if kind == "frame" and payload.sensor not in self.publishers:
                continue
            if first_stamp is None:
                first_stamp = stamp
            last_stamp = stamp
            if kind == "frame":
                frame_id = self.frame_ids.get(payload.sensor, payload.sensor)
                msg = make_pointcloud2(payload, frame_id, layout="livox")
            else:
                msg = PointStamped()
                msg.header.stamp = seconds_to_time_msg(stamp)
                msg.header.frame_id = self.ground_truth_frame_id
                msg.point.x, msg.point.y, msg.point.z = (float(v) for v in payload)
            if rate > 0:
                due = started + (stamp - first_stamp) / rate
                delay = due - time.monotonic()
                if delay > 0:
                    if stop is not None:
                        if stop.wait(delay):
                            stats.stopped = True
                            break
                    else:
                        time.sleep(delay)
                else:
                    stats.max_behind_seconds = max(stats.max_behind_seconds, -delay)
            if kind == "frame":
                self.publishers[payload.sensor].publish(msg)
                stats.frames[payload.sensor] = stats.frames.get(payload.sensor, 0) + 1
                if on_frame is not None:
                    on_frame(payload)
            elif self.ground_truth_publisher is not None:
                self.ground_truth_publisher.publish(msg)
                stats.ground_truth += 1
        stats.wall_seconds = time.monotonic() - started
        stats.stamp_seconds = 0.0 if first_stamp is None else last_stamp - first_stamp
        return stats

    def play_sequence(
        self, sequence: Sequence, rate: float = 1.0, stop: threading.Event | None = None
    ) -> ReplayStats:
        """:meth:`play` a whole :class:`Sequence` (its frames and ground truth)."""
        return self.play(sequence.frames, sequence.ground_truth, rate=rate, stop=stop)

    def destroy(self) -> None:
        """Destroy the publishers (the node stays)."""
        for pub in self.publishers.values():
            self.node.destroy_publisher(pub)
        if self.ground_truth_publisher is not None:
            self.node.destroy_publisher(self.ground_truth_publisher)


def _merged_items(
    frames: Iterable[Frame], ground_truth: TimedPositions | None
) -> Iterator[tuple[str, float, object]]:
    """Frames and ground-truth points in stamp order (frames first on equal stamps)."""
    frame_items = ((f.stamp, 0, f.sensor, "frame", f) for f in frames)
    gt_items: Iterable[tuple[float, int, str, str, object]] = ()
    if ground_truth is not None and len(ground_truth):
        gt_items = (
            (float(t), 1, "", "gt", xyz)
            for t, xyz in zip(ground_truth.stamps, ground_truth.xyz, strict=True)
        )
    for stamp, _, _, kind, payload in heapq.merge(frame_items, gt_items, key=lambda item: item[:3]):
        yield kind, stamp, payload
