"""Command-line options shared by subcommands that read a recording (bags or folders)."""

from __future__ import annotations

import argparse
from typing import Any

from clusterfilter_ros.core.frame import SENSORS
from clusterfilter_ros.errors import InputError


def add_input_options(parser: argparse.ArgumentParser, ground_truth: bool = True) -> None:
    """``--topic TOPIC=SENSOR`` (repeatable), ``--sensors`` and, with ``ground_truth``,
    ``--ground-truth-topic``."""
    group = parser.add_argument_group("input selection")
    group.add_argument(
        "--topic",
        action="append",
        default=[],
        metavar="TOPIC=SENSOR",
        help="bags: read lidar TOPIC as SENSOR (avia or mid360); repeatable. Default: every "
        "PointCloud2/CustomMsg topic whose name contains 'avia' or 'mid360'/'360'",
    )
    if ground_truth:
        group.add_argument(
            "--ground-truth-topic",
            metavar="TOPIC",
            help="bags: PointStamped/PoseStamped ground-truth topic (default: "
            "/uav/ground_truth if present)",
        )
    group.add_argument(
        "--sensors",
        metavar="NAMES",
        help="comma-separated sensors to read, e.g. 'avia' (default: all)",
    )


def parse_topic_mapping(values: list[str]) -> dict[str, str] | None:
    """``["/a=avia", "/b=mid360"]`` -> ``{"/a": "avia", "/b": "mid360"}`` (None if empty)."""
    mapping: dict[str, str] = {}
    for value in values:
        topic, sep, sensor = value.partition("=")
        if not sep or not topic.strip() or not sensor.strip():
            raise InputError(f"--topic {value!r}: expected TOPIC=SENSOR, e.g. /livox/lidar=avia")
        if sensor.strip() not in SENSORS:
            # An unknown sensor name would skip that lidar's own filters without a word.
            raise InputError(f"--topic {value!r}: the sensor must be one of {', '.join(SENSORS)}")
        mapping[topic.strip()] = sensor.strip()
    return mapping or None


def input_kwargs_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """Keyword arguments for :func:`clusterfilter_ros.io.dataset.iter_input_frames` & co."""
    sensors = [s.strip() for s in args.sensors.split(",") if s.strip()] if args.sensors else None
    return {"topics": parse_topic_mapping(args.topic), "sensors": sensors}
