"""Parameters of the ROS node itself (topics, frames, extrinsics, timing). ROS-free.

The detector's own parameters are :data:`clusterfilter_ros.core.params.DETECTOR_PARAMS`;
the node declares both lists. Parameters marked ``read_only`` are fixed once the node
has started (topics and QoS are set up from them); the rest can be changed at run time
with ``ros2 param set`` and are validated by their :class:`ParamSpec`.
"""

from __future__ import annotations

from clusterfilter_ros.core.params import ParamSpec

#: The node's default name (``ros2 run clusterfilter_ros detector``).
NODE_NAME = "clusterfilter_detector"

#: Identity transform, ``[x, y, z, qx, qy, qz, qw]``.
IDENTITY_EXTRINSIC: list[float] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]

NODE_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec(
        "avia_topic",
        "str",
        "/livox/avia",
        "PointCloud2 topic of the upward-looking Livox Avia.",
        group="node",
        read_only=True,
    ),
    ParamSpec(
        "mid360_topic",
        "str",
        "/livox/mid360",
        "PointCloud2 topic of the all-round Livox Mid360.",
        group="node",
        read_only=True,
    ),
    ParamSpec(
        "frame_id",
        "str",
        "map",
        "frame_id written in the headers of /uav/pose, /uav/points and /uav/path.",
        group="node",
    ),
    ParamSpec(
        "avia_extrinsic",
        "float_list",
        list(IDENTITY_EXTRINSIC),
        "Pose of the Avia in the output frame: x, y, z (m), qx, qy, qz, qw "
        "(normalised on use). Applied to every Avia point before detection.",
        minimum=-10000.0,
        maximum=10000.0,
        length=7,
        group="node",
    ),
    ParamSpec(
        "mid360_extrinsic",
        "float_list",
        list(IDENTITY_EXTRINSIC),
        "Pose of the Mid360 in the output frame: x, y, z (m), qx, qy, qz, qw "
        "(normalised on use). Applied to every Mid360 point before detection.",
        minimum=-10000.0,
        maximum=10000.0,
        length=7,
        group="node",
    ),
    ParamSpec(
        "qos_depth",
        "int",
        10,
        "History depth of the two sensor-data (best-effort) PointCloud2 subscriptions.",
        minimum=1,
        maximum=1000,
        group="node",
        read_only=True,
    ),
    ParamSpec(
        "min_frame_interval",
        "float",
        0.05,
        "Shortest interval (s) between two stamps of one lidar (0.1 s at 10 Hz); the merge "
        "releases a frame without waiting for a lidar whose next frame cannot sort before "
        "it. 0 always waits for the other lidar's next frame.",
        minimum=0.0,
        maximum=10.0,
        group="node",
    ),
    ParamSpec(
        "sync_timeout",
        "float",
        0.25,
        "Longest wait (s, wall clock) for the other lidar before a frame is processed; "
        "frames are merged in header-stamp order, 0 processes them in arrival order.",
        minimum=0.0,
        maximum=10.0,
        group="node",
    ),
    ParamSpec(
        "max_queue",
        "int",
        50,
        "Frames waiting for the detector; when full the oldest is dropped and counted.",
        minimum=1,
        maximum=10000,
        group="node",
    ),
    ParamSpec(
        "recluster_in_background",
        "bool",
        True,
        "Run each re-clustering (every recluster_period) on a worker thread, so frames "
        "arriving meanwhile are processed at once with the current track instead of "
        "waiting tens of milliseconds; false runs it inside the frame that triggers it, "
        "which makes the poses reproducible (equal to `clusterfilter detect --mode "
        "stream`).",
        group="node",
        read_only=True,
    ),
    ParamSpec(
        "backwards_tolerance",
        "float",
        0.5,
        "A header stamp earlier than the previous one of the same lidar by more than this "
        "(s), e.g. a looped bag, resets the detector; smaller steps back are dropped.",
        minimum=0.0,
        maximum=3600.0,
        group="node",
    ),
    ParamSpec(
        "path_length",
        "int",
        200,
        "Number of recent estimates kept in /uav/path.",
        minimum=1,
        maximum=100000,
        group="node",
    ),
    ParamSpec(
        "diagnostics_period",
        "float",
        1.0,
        "Period (s) of the /diagnostics message.",
        minimum=0.05,
        maximum=60.0,
        group="node",
        read_only=True,
    ),
    ParamSpec(
        "stale_timeout",
        "float",
        1.0,
        "A lidar silent for longer than this (s, wall clock) makes /diagnostics WARN; "
        "both silent makes it STALE.",
        minimum=0.01,
        maximum=3600.0,
        group="node",
    ),
)
