"""Parameters of the ROS node itself (topics, frames, extrinsics). ROS-free."""

from __future__ import annotations

from clusterfilter_ros.core.params import ParamSpec

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
)
