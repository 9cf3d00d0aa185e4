"""``builtin_interfaces/Time`` from and to float seconds (rounding rules of the I/O layer)."""

from __future__ import annotations

from builtin_interfaces.msg import Time as TimeMsg

from clusterfilter_ros.io.pointcloud2 import MAX_ROS2_SEC, seconds_to_stamp, stamp_to_seconds


def seconds_to_time_msg(stamp: float) -> TimeMsg:
    """A ``builtin_interfaces/Time`` for ``stamp`` seconds (nanoseconds rounded)."""
    # builtin_interfaces/Time.sec is an int32 (negative stamps are allowed, as before).
    sec, nanosec = seconds_to_stamp(stamp, MAX_ROS2_SEC, -MAX_ROS2_SEC - 1)
    return TimeMsg(sec=int(sec), nanosec=int(nanosec))


def time_msg_to_seconds(stamp: TimeMsg) -> float:
    """Seconds of a ``builtin_interfaces/Time``."""
    return stamp_to_seconds(stamp)
