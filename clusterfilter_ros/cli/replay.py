"""``clusterfilter replay``: publish a recording on the detector's topics, paced by stamps."""

from __future__ import annotations

import argparse
import math

from clusterfilter_ros.cli._input_args import add_input_options, input_kwargs_from_args
from clusterfilter_ros.errors import ClusterfilterError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "replay",
        help="publish a challenge folder or bag as Livox PointCloud2 (+ ground truth)",
        description="Publish INPUT's lidar frames as livox_ros_driver2-layout PointCloud2 on "
        "the detector's topics and its ground truth as PointStamped, in stamp order, paced "
        "by the stamps. Waits for the detector to subscribe first.",
    )
    p.add_argument("input", help="challenge sequence folder, ROS 1 .bag or ROS 2 bag")
    p.add_argument(
        "--rate",
        type=float,
        default=1.0,
        help="playback speed (1 = real time, 2 = twice as fast, 0 = as fast as possible)",
    )
    p.add_argument("--loop", action="store_true", help="start again at the end (Ctrl-C stops)")
    p.add_argument("--avia-topic", default="/livox/avia", help="default: %(default)s")
    p.add_argument("--mid360-topic", default="/livox/mid360", help="default: %(default)s")
    p.add_argument(
        "--gt-topic",
        default="/uav/ground_truth",
        help="publish ground truth as PointStamped here, '' for none (default: %(default)s)",
    )
    p.add_argument("--ground-truth", help="ground truth CSV or folder replacing the input's own")
    p.add_argument(
        "--wait",
        type=float,
        default=30.0,
        help="seconds to wait for subscribers before giving up (default: %(default)s)",
    )
    p.add_argument(
        "--wait-for",
        action="append",
        default=[],
        metavar="TOPIC",
        help="also wait until TOPIC has a subscriber, e.g. --wait-for /uav/pose (repeatable)",
    )
    p.add_argument(
        "--no-wait", action="store_true", help="start at once, even with nobody subscribed"
    )
    add_input_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not math.isfinite(args.rate) or args.rate < 0:
        raise ClusterfilterError(f"--rate must be a number >= 0, got {args.rate}")
    if not math.isfinite(args.wait) or args.wait < 0:
        raise ClusterfilterError(f"--wait must be a number of seconds >= 0, got {args.wait}")
    from clusterfilter_ros.dds import apply_loopback_defaults
    from clusterfilter_ros.io.dataset import open_input

    sequence = open_input(
        args.input,
        ground_truth=args.ground_truth,
        ground_truth_topic=args.ground_truth_topic,
        **input_kwargs_from_args(args),
    )
    if not sequence.frames:
        raise ClusterfilterError(f"{args.input}: no lidar frames to replay")
    apply_loopback_defaults()

    import rclpy
    from rclpy.executors import ExternalShutdownException

    from clusterfilter_ros.core.frame import AVIA, MID360
    from clusterfilter_ros.ros.replay import Replayer

    rclpy.init(args=["clusterfilter-replay"])
    node = rclpy.create_node("clusterfilter_replay")
    try:
        replayer = Replayer(
            node,
            topics={AVIA: args.avia_topic, MID360: args.mid360_topic},
            ground_truth_topic=args.gt_topic or None,
        )
        if not args.no_wait:
            print(f"replay: waiting up to {args.wait:g} s for subscribers ...", flush=True)
            if not replayer.wait_for_subscribers(args.wait, args.wait_for):
                missing = ", ".join(replayer.missing_subscribers(args.wait_for))
                raise ClusterfilterError(
                    f"no subscriber on {missing} after {args.wait:g} s "
                    "(is the detector running, with the same ROS_DOMAIN_ID?)"
                )
        counts = {}
        for f in sequence.frames:
            counts[f.sensor] = counts.get(f.sensor, 0) + 1
        n_gt = 0 if sequence.ground_truth is None else len(sequence.ground_truth)
        print(
            f"replay: {sequence.name}: {counts} frames, {n_gt} ground-truth points, "
            f"{sequence.end - sequence.start:.1f} s at rate {args.rate:g}",
            flush=True,
        )
        while True:
            stats = replayer.play_sequence(sequence, rate=args.rate)
            print(
                f"replay: published {stats.frames} frames and {stats.ground_truth} "
                f"ground-truth points in {stats.wall_seconds:.1f} s "
                f"(worst lag behind schedule {stats.max_behind_seconds * 1000:.0f} ms)",
                flush=True,
            )
            if not args.loop:
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
