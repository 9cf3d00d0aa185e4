"""``clusterfilter info``: what a recording holds (sensors, rates, points, ground truth)."""

from __future__ import annotations

import argparse

from clusterfilter_ros.cli._input_args import add_input_options, input_kwargs_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "info",
        help="summarise a recording: sensors, frame counts, rates, points per frame, GT",
        description="Read a challenge sequence folder (or a folder of them) or a bag and "
        "print per sensor the number of frames, the frame rate, points per frame and the "
        "time span, and whether ground truth is present. Bags also list their topics.",
    )
    p.add_argument("input", metavar="INPUT", help="sequence folder(s), .bag file or ROS 2 bag")
    add_input_options(p)
    p.set_defaults(func=run)


def describe(path: str, select: dict, ground_truth_topic: str | None) -> list[str]:
    """Lines describing one recording."""
    import numpy as np

    from clusterfilter_ros.io.dataset import (
        detect_input_kind,
        iter_input_frames,
        read_input_ground_truth,
    )

    kind = detect_input_kind(path)
    lines = [f"{path}  ({kind})"]
    if kind in ("rosbag1", "rosbag2"):
        from clusterfilter_ros.io.bags import bag_summary

        summary = bag_summary(path)
        lines.append(f"  storage: {summary.storage}")
        for t in summary.topics.values():
            lines.append(f"  topic {t.topic}: {t.msgtype}, {t.count} messages")
    stats: dict[str, tuple[list[float], list[int]]] = {}
    for frame in iter_input_frames(path, **select):
        stamps, counts = stats.setdefault(frame.sensor, ([], []))
        stamps.append(frame.stamp)
        counts.append(len(frame))
    if not stats:
        lines.append("  no lidar frames")
    for sensor, (stamps, counts) in sorted(stats.items()):
        t = np.asarray(stamps)
        c = np.asarray(counts)
        span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
        rate = (len(t) - 1) / span if span > 0 else float("nan")
        lines.append(
            f"  {sensor}: {len(t)} frames, {rate:.2f} Hz, {span:.2f} s "
            f"({t[0]:.6f} .. {t[-1]:.6f}), points/frame min {c.min()} "
            f"median {int(np.median(c))} max {c.max()}, {c.sum()} in total"
        )
    gt = read_input_ground_truth(path, ground_truth_topic)
    if gt is None or not len(gt):
        lines.append("  ground truth: none")
    else:
        gspan = float(gt.stamps[-1] - gt.stamps[0])
        lo, hi = gt.xyz.min(axis=0), gt.xyz.max(axis=0)
        lines.append(
            f"  ground truth: {len(gt)} positions over {gspan:.2f} s "
            f"({gt.stamps[0]:.6f} .. {gt.stamps[-1]:.6f}), "
            f"x {lo[0]:.1f}..{hi[0]:.1f} y {lo[1]:.1f}..{hi[1]:.1f} z {lo[2]:.1f}..{hi[2]:.1f} m"
        )
    return lines


def run(args: argparse.Namespace) -> int:
    from clusterfilter_ros.io.dataset import list_inputs

    select = input_kwargs_from_args(args)
    for path in list_inputs(args.input):
        print("\n".join(describe(str(path), select, args.ground_truth_topic)))
    return 0
