"""``clusterfilter evaluate``: accuracy of a detection CSV against ground truth."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "evaluate",
        help="compare a detection CSV with ground truth (coverage, detection rate, errors)",
        description="Each ground-truth sample gets the prediction interpolated between the "
        "two nearest prediction rows if both lie within --max-gap seconds, else none. "
        "Reports coverage, detection rate (within --hit-radius), mean/RMSE/median/p95 3D "
        "error, MSE (m^2) and false-alarm seconds. GT may be a CSV, a ground_truth folder, "
        "a sequence folder or a bag (its ground-truth topic); a sequence folder or bag "
        "without ground truth counts as drone-free (every report is a false alarm).",
    )
    p.add_argument("pred", metavar="PRED.csv", help="timestamp,x,y,z[,...] estimates")
    p.add_argument(
        "gt", metavar="GT", help="ground truth CSV, ground_truth folder, sequence folder or bag"
    )
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")
    p.add_argument("--plot", metavar="OUT.png", help="write top/side views and error over time")
    p.add_argument("--max-gap", type=float, default=0.3, help="seconds (default 0.3)")
    p.add_argument("--hit-radius", type=float, default=2.0, help="metres (default 2.0)")
    p.add_argument(
        "--duration",
        type=float,
        help="recording length in seconds for the false-alarm fraction "
        "(default: ground-truth span, or the recording's span when drone-free)",
    )
    p.add_argument(
        "--ground-truth-topic",
        metavar="TOPIC",
        help="GT is a bag: its PointStamped/PoseStamped ground-truth topic (default: "
        "/uav/ground_truth if present, else the bag counts as drone-free)",
    )
    p.set_defaults(func=run)


def load_truth(path: str, ground_truth_topic: str | None = None):
    """(ground truth TimedPositions, duration or None) from a CSV/folder/sequence/bag.

    A sequence folder or bag without ground truth gives an empty truth (drone-free) and
    its recording span as the duration.
    """
    import numpy as np

    from clusterfilter_ros.core.frame import TimedPositions
    from clusterfilter_ros.errors import InputError
    from clusterfilter_ros.io.challenge import (
        GROUND_TRUTH_FOLDER,
        is_sequence_folder,
        list_lidar_files,
    )
    from clusterfilter_ros.io.dataset import is_bag, read_input_ground_truth
    from clusterfilter_ros.io.groundtruth import read_ground_truth

    p = Path(path)
    bag = is_bag(p)
    if ground_truth_topic and not bag:
        raise InputError(f"{p}: --ground-truth-topic applies to bags only")
    if bag:
        from clusterfilter_ros.io.bags import bag_summary

        gt = read_input_ground_truth(p, ground_truth_topic)
        summary = bag_summary(p)
        span = summary.end - summary.start
        duration = span if span > 0 else None
        if gt is None:
            return TimedPositions(np.empty(0), np.empty((0, 3))), duration
        return gt, duration
    if p.is_dir() and is_sequence_folder(p):
        files = list_lidar_files(p)
        duration = (files[-1].stamp - files[0].stamp) if len(files) > 1 else None
        if not (p / GROUND_TRUTH_FOLDER).is_dir():
            return TimedPositions(np.empty(0), np.empty((0, 3))), duration
        return read_ground_truth(p), duration
    return read_ground_truth(p), None


def run(args: argparse.Namespace) -> int:
    from clusterfilter_ros.core.evaluation import evaluate
    from clusterfilter_ros.errors import InputError
    from clusterfilter_ros.io.groundtruth import read_positions_csv

    for option, value in (("--max-gap", args.max_gap), ("--hit-radius", args.hit_radius)):
        if not math.isfinite(value) or value <= 0:
            raise InputError(f"{option} must be a positive number, got {value}")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise InputError(f"--duration must be a positive number of seconds, got {args.duration}")
    pred = read_positions_csv(args.pred)
    gt, duration = load_truth(args.gt, args.ground_truth_topic)
    if args.duration is not None:
        duration = args.duration
    result = evaluate(pred, gt, args.max_gap, args.hit_radius, duration=duration)
    metrics = result.as_dict()
    if args.json:
        print(json.dumps(metrics, indent=2))
    else:
        for name, value in metrics.items():
            text = (
                "n/a" if value is None else (f"{value:.4f}" if isinstance(value, float) else value)
            )
            print(f"{name:>26}: {text}")
    if args.plot:
        from clusterfilter_ros.plots import plot_evaluation

        plot_evaluation(gt if len(gt) else None, pred, args.plot, title=Path(args.pred).name)
        print(f"plot -> {args.plot}", file=sys.stderr)
    return 0
