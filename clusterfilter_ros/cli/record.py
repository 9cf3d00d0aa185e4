"""``clusterfilter record``: record /uav/pose into a CSV (and a ROS 2 bag) for the evaluator."""

from __future__ import annotations

import argparse
import sys
import time

from clusterfilter_ros.errors import ClusterfilterError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "record",
        help="record the detector's /uav/pose into timestamp,x,y,z CSV (and a bag)",
        description="Subscribe to /uav/pose and write every pose received as a "
        "timestamp,x,y,z CSV (atomically) when stopped: after --duration, after "
        "--until-idle seconds without a pose, or on Ctrl-C/SIGTERM.",
    )
    p.add_argument("output", help="CSV file to write")
    p.add_argument("--bag", help="also write a ROS 2 bag (sqlite3) folder with the messages")
    p.add_argument("--points", help="also write the drone points of /uav/points as .npy")
    p.add_argument("--topic", default="/uav/pose", help="PoseStamped topic (default %(default)s)")
    p.add_argument("--points-topic", default="/uav/points", help="PointCloud2 topic for --points")
    stop = p.add_mutually_exclusive_group()
    stop.add_argument("--duration", type=float, help="stop after this many seconds")
    stop.add_argument(
        "--until-idle",
        type=float,
        metavar="S",
        help="stop once S seconds pass without a pose (counted from the first pose)",
    )
    stop.add_argument(
        "--until-frames",
        type=int,
        metavar="N",
        help="stop once the detector's /diagnostics report N input frames handled "
        "(processed, dropped or rejected) and none queued, e.g. the replay's frame count",
    )
    p.add_argument(
        "--timeout",
        type=float,
        help="with --until-idle/--until-frames: stop after this many seconds regardless",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    for name in ("duration", "until_idle", "until_frames", "timeout"):
        value = getattr(args, name)
        if value is not None and not value > 0:
            raise ClusterfilterError(f"--{name.replace('_', '-')} must be > 0, got {value}")
    from pathlib import Path

    if args.bag and Path(args.bag).exists():
        raise ClusterfilterError(f"bag {args.bag} already exists; choose a new folder")
    from clusterfilter_ros.dds import apply_loopback_defaults

    apply_loopback_defaults()
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from clusterfilter_ros.ros.record import PoseRecorder
    from clusterfilter_ros.ros.signals import shutdown_race, stop_on_signals

    rclpy.init(args=["clusterfilter-record"], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("clusterfilter_record")
    recorder = PoseRecorder(
        node,
        pose_topic=args.topic,
        points_topic=args.points_topic if args.points else None,
        keep_messages=bool(args.bag),
        watch_diagnostics=args.until_frames is not None,
    )
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    started = time.monotonic()
    reason = "stopped"
    print(f"record: recording {args.topic} ...", flush=True)
    matched = False
    with stop_on_signals() as stop:
        try:
            while True:
                executor.spin_once(timeout_sec=0.1)
                if stop.is_set():
                    reason = "interrupted"
                    break
                now = time.monotonic()
                if not matched and recorder.matched_publishers() > 0:
                    matched = True
                    print(f"record: matched a publisher of {args.topic}", flush=True)
                if args.duration is not None and now - started >= args.duration:
                    reason = f"{args.duration:g} s elapsed"
                    break
                if args.until_idle is not None:
                    idle = recorder.idle_for(now)
                    if idle is not None and idle >= args.until_idle:
                        reason = f"no pose for {args.until_idle:g} s"
                        break
                if args.until_frames is not None:
                    handled = recorder.frames_handled()
                    if handled is not None and handled[0] >= args.until_frames and handled[1] == 0:
                        # The detector's last poses are published before its diagnostics
                        # count them, but give the transport a moment.
                        end = time.monotonic() + 0.5
                        while time.monotonic() < end:
                            executor.spin_once(timeout_sec=0.05)
                        reason = f"detector handled {handled[0]} frames"
                        break
                if args.timeout is not None and now - started >= args.timeout:
                    reason = f"timeout of {args.timeout:g} s"
                    break
        except (KeyboardInterrupt, ExternalShutdownException):
            reason = "interrupted"
        except RuntimeError as exc:
            if not shutdown_race(exc):
                raise
            reason = "interrupted"
        finally:
            executor.shutdown(timeout_sec=1.0)
            written = [str(recorder.write_csv(args.output))]
            if args.points:
                written.append(str(recorder.write_points(args.points)))
            if args.bag:
                written.append(str(recorder.write_bag(args.bag)))
            n = len(recorder)
            if n:
                pos = recorder.positions()
                print(f"record: poses stamped {pos.stamps[0]:.3f} .. {pos.stamps[-1]:.3f} s")
            recorder.destroy()
            node.destroy_node()
            rclpy.try_shutdown()
    print(f"record: {reason}; {n} poses written to {', '.join(written)}", flush=True)
    if n == 0:
        print(f"record: warning: no message arrived on {args.topic}", file=sys.stderr)
    return 0
