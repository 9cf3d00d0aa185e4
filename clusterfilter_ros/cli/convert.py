"""``clusterfilter convert``: between challenge sequence folders and ROS 1 / ROS 2 bags."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from clusterfilter_ros.cli._input_args import add_input_options, input_kwargs_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "convert",
        help="convert a recording between challenge folders and ROS 1/ROS 2 bags",
        description="Convert a challenge sequence folder or a bag (ROS 1 .bag, ROS 2 "
        "sqlite3/mcap) into a challenge folder (mmaud), a ROS 2 bag or a ROS 1 bag. Bags "
        "get livox_ros_driver2-layout PointCloud2 (or CustomMsg) on /livox/avia and "
        "/livox/mid360 and PointStamped ground truth on /uav/ground_truth. Frames are "
        "streamed, so long recordings do not need to fit in memory.",
    )
    p.add_argument("input", metavar="INPUT", help="sequence folder, .bag file or ROS 2 bag")
    p.add_argument("output", metavar="OUTPUT", help="folder (mmaud, rosbag2) or .bag file")
    p.add_argument("--to", choices=("mmaud", "rosbag2", "rosbag1"), required=True)
    p.add_argument(
        "--storage", choices=("sqlite3", "mcap"), default="sqlite3", help="rosbag2 storage"
    )
    p.add_argument(
        "--lidar-msg",
        choices=("PointCloud2", "CustomMsg"),
        default="PointCloud2",
        help="bag output: message type of the lidar topics (default %(default)s)",
    )
    p.add_argument(
        "--layout",
        choices=("livox", "xyz", "xyzi"),
        default="livox",
        help="PointCloud2 output field layout (default: livox_ros_driver2's 26-byte points)",
    )
    p.add_argument("--avia-topic", default="/livox/avia", help="bag output (%(default)s)")
    p.add_argument("--mid360-topic", default="/livox/mid360", help="bag output (%(default)s)")
    p.add_argument(
        "--out-ground-truth-topic",
        default="/uav/ground_truth",
        help="bag output: ground-truth topic, '' to leave ground truth out (%(default)s)",
    )
    p.add_argument(
        "--pad",
        choices=("real", "none"),
        default="real",
        help="mmaud output: zero-pad files to the real row counts (Mid360 19968/20064, "
        "Avia 24000) or write only the points (default %(default)s)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing OUTPUT")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_input_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from clusterfilter_ros.core.frame import AVIA, MID360
    from clusterfilter_ros.errors import InputError
    from clusterfilter_ros.io.challenge import REAL_PAD_ROWS
    from clusterfilter_ros.io.dataset import (
        count_input_frames,
        iter_input_frames,
        read_input_ground_truth,
        write_output_frames,
    )

    out_path = Path(args.output)
    if out_path.exists() and not args.overwrite:
        raise InputError(f"output {out_path} already exists (use --overwrite to replace it)")
    select = input_kwargs_from_args(args)
    total = count_input_frames(args.input, **select)
    if total == 0:
        raise InputError(f"{args.input}: no lidar frames to convert")
    ground_truth = read_input_ground_truth(args.input, args.ground_truth_topic)
    frames = iter_input_frames(args.input, **select)
    if args.to == "mmaud":
        writer_kw: dict = {"pad_rows": REAL_PAD_ROWS if args.pad == "real" else None}
    else:
        writer_kw = {
            "topics": {AVIA: args.avia_topic, MID360: args.mid360_topic},
            "ground_truth_topic": args.out_ground_truth_topic or None,
            "lidar_msg": args.lidar_msg,
            "layout": args.layout,
        }
        if args.to == "rosbag2":
            writer_kw["storage"] = args.storage
    with tqdm(
        total=total, unit="frame", desc="convert", disable=args.quiet, file=sys.stderr
    ) as bar:
        out = write_output_frames(
            frames,
            args.output,
            fmt=args.to,
            ground_truth=ground_truth,
            overwrite=args.overwrite,
            progress=bar.update,
            **writer_kw,
        )
    n_gt = len(ground_truth) if ground_truth is not None else 0
    print(f"convert: wrote {total} frames and {n_gt} ground-truth positions to {out}")
    return 0
