"""Latency of the detector node across processes: replay publish -> /uav/pose received.

Starts the detector as its own process (loopback DDS, a random ROS domain), then from
this process replays a simulated scenario at real time, records when each frame was
published and when the pose for that frame's stamp arrived, and collects the node's
own /diagnostics (processing time per frame, receipt-to-publish latency).

    python benchmarks/bench_node.py [--scenario default] [--seed 0] [--rate 1]
                                    [--quick] [--json OUT.json]
                                    [--param NAME=VALUE ...]

With ``--json`` (as ``run_all.py`` calls it) the result also goes to a JSON file in the
benchmark suite's format: publish -> pose latency p50/p95/p99, the node process's CPU
use during the replay (psutil, % of one core), and the raw latencies for the plot.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from clusterfilter_ros.ros import processes  # noqa: E402


def percentiles(values: list[float]) -> str:
    if not values:
        return "n/a"
    a = np.asarray(values)
    return (
        f"p50 {np.percentile(a, 50):.1f}  p95 {np.percentile(a, 95):.1f}  "
        f"p99 {np.percentile(a, 99):.1f}  max {a.max():.1f}  (n={a.size})"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="default")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rate", type=float, default=1.0)
    parser.add_argument("--duration", type=float, default=None)
    parser.add_argument("--quick", action="store_true", help="a 4 s replay (CI smoke run)")
    parser.add_argument("--json", type=Path, help="write the suite's result dictionary here")
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a detector node parameter (repeatable), e.g. recluster_in_background=false",
    )
    parser.add_argument("--input", help="replay this challenge folder or bag instead of simulating")
    parser.add_argument(
        "--target-offset", default=None, help="x,y,z for target_offset (default: sim's prism)"
    )
    args = parser.parse_args()
    if args.quick and args.duration is None:
        args.duration = 4.0
    wall_start = time.perf_counter()

    from clusterfilter_ros.io.pointcloud2 import seconds_to_stamp
    from clusterfilter_ros.resources import config_file
    from clusterfilter_ros.sim.scenarios import simulate

    if args.input:
        from clusterfilter_ros.io.dataset import open_input

        sequence = open_input(args.input)
        prism = [0.0, 0.0, 0.0]
        label = args.input
    else:
        simulated = simulate(args.scenario, seed=args.seed, duration=args.duration)
        sequence = simulated.sequence
        prism = np.asarray(simulated.prism_offset).reshape(3)
        label = f"scenario {args.scenario} seed {args.seed}"
    env = processes.demo_environment()
    os.environ.update(env)  # this process joins the same confined domain
    log_dir = Path(os.environ.get("TMPDIR", "/tmp")) / f"bench_node_{os.getpid()}"
    offset = args.target_offset or ",".join(repr(float(v)) for v in prism)
    detector = processes.start(
        "detector",
        processes.cli_command(
            "detector",
            "--params-file",
            str(config_file("detector.yaml")),
            "-p",
            f"target_offset={offset}",
            *[arg for item in args.param for arg in ("-p", item)],
        ),
        env,
        log_dir,
    )
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import SingleThreadedExecutor

    from clusterfilter_ros.ros.record import RECORD_QOS
    from clusterfilter_ros.ros.replay import Replayer

    rclpy.init(args=["bench_node"])
    node = rclpy.create_node("bench_node")
    published: dict[tuple[int, int], float] = {}
    received: dict[tuple[int, int], float] = {}
    node_processing: list[float] = []
    node_latency: list[float] = []
    node_processing_mean: list[float] = []
    node_latency_mean: list[float] = []

    def on_pose(msg: PoseStamped) -> None:
        received[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = time.monotonic()

    def on_diag(msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if "processing_ms_max" in values and int(values["frames_processed"]) > 0:
                node_processing.append(float(values["processing_ms_max"]))
                node_latency.append(float(values["latency_ms_max"]))
                node_processing_mean.append(float(values["processing_ms_mean"]))
                node_latency_mean.append(float(values["latency_ms_mean"]))

    node.create_subscription(PoseStamped, "/uav/pose", on_pose, RECORD_QOS)
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, RECORD_QOS)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    replayer = Replayer(node)
    try:
        if not replayer.wait_for_subscribers(60.0, ["/uav/pose"]):
            print("detector did not subscribe:\n" + detector.log_tail(), file=sys.stderr)
            return 1

        def on_frame(frame) -> None:
            published[seconds_to_stamp(frame.stamp)] = time.monotonic()

        import psutil

        node_process = psutil.Process(detector.process.pid)
        cpu_before = node_process.cpu_times()
        cpu_wall = time.monotonic()
        stats = replayer.play(
            sequence.frames, sequence.ground_truth, rate=args.rate, on_frame=on_frame
        )
        cpu_after = node_process.cpu_times()
        cpu_wall = time.monotonic() - cpu_wall
        node_cpu_percent = (
            100.0
            * (cpu_after.user + cpu_after.system - cpu_before.user - cpu_before.system)
            / cpu_wall
        )
        time.sleep(3.0)
    finally:
        code = detector.interrupt()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()
    latencies = [(received[k] - published[k]) * 1000.0 for k in received if k in published]
    n_points = {
        s: int(np.mean([len(f) for f in sequence.frames if f.sensor == s]))
        for s in sequence.sensors()
    }
    print(
        f"{label}: {stats.total_frames} frames "
        f"({n_points} points/frame on average) replayed at rate {args.rate:g} "
        f"in {stats.wall_seconds:.1f} s"
    )
    print(f"poses received: {len(received)}; detector exit code {code}")
    if args.param:
        print(f"node parameters: {' '.join(args.param)}")
    print(f"publish -> pose received (ms), per pose:      {percentiles(latencies)}")
    print(f"node processing per frame (ms), worst per 1 s: {percentiles(node_processing)}")
    print(f"node receipt -> done (ms), worst per 1 s:      {percentiles(node_latency)}")
    print(f"node processing per frame (ms), mean per 1 s:  {percentiles(node_processing_mean)}")
    print(f"node receipt -> done (ms), mean per 1 s:       {percentiles(node_latency_mean)}")
    print(f"node CPU during the replay: {node_cpu_percent:.1f}% of one core")
    print(detector.log_tail(1))
    if args.json:
        _write_json(
            args,
            stats,
            latencies,
            node_cpu_percent,
            n_points,
            len(received),
            code,
            node_processing_mean,
            node_latency_mean,
            time.perf_counter() - wall_start,
        )
    return 0


def _write_json(
    args: argparse.Namespace,
    stats,
    latencies: list[float],
    node_cpu_percent: float,
    n_points: dict[str, int],
    poses: int,
    exit_code: int,
    node_processing_mean: list[float],
    node_latency_mean: list[float],
    seconds: float,
) -> None:
    """The result in the benchmark suite's format (see benchmarks/benchlib.py)."""
    import json

    from benchlib import machine_info, target_row
    from benchlib import percentiles as pct

    lat = pct(latencies, (50, 95, 99))
    command = (
        f"python benchmarks/bench_node.py --scenario {args.scenario} --seed {args.seed}"
        + (f" --rate {args.rate:g}" if args.rate != 1.0 else "")
        + (" --quick" if args.quick else "")
        + "".join(f" --param {item}" for item in args.param)
    )
    p99 = lat["p99"] if latencies else None
    result = {
        "benchmark": "node",
        "command": command,
        "machine": machine_info(),
        "quick": bool(args.quick),
        "seconds": seconds,
        "tables": [
            {
                "id": "node_latency",
                "title": "Detector node: frame publication to /uav/pose, across processes",
                "columns": [
                    "scenario",
                    "rate",
                    "frames published",
                    "poses",
                    "p50 ms",
                    "p95 ms",
                    "p99 ms",
                    "max ms",
                    "node CPU % of one core",
                    "node processing mean ms",
                    "node receipt to done mean ms",
                ],
                "rows": [
                    [
                        f"{args.scenario} (seed {args.seed})",
                        f"{args.rate:g}x",
                        stats.total_frames,
                        poses,
                        lat["p50"],
                        lat["p95"],
                        lat["p99"],
                        max(latencies) if latencies else None,
                        node_cpu_percent,
                        float(np.mean(node_processing_mean)) if node_processing_mean else None,
                        float(np.mean(node_latency_mean)) if node_latency_mean else None,
                    ]
                ],
                "note": "Detector in its own process (installed CLI, config/detector.yaml), "
                "replay and pose subscriber in the benchmark process; loopback Fast DDS "
                "profile, random ROS domain. Latency = wall time the pose for a frame's "
                "stamp arrived minus wall time that frame was published. Points per frame: "
                + ", ".join(f"{k} {v:,}" for k, v in n_points.items())
                + f". Detector exit code {exit_code}.",
            }
        ],
        "series": {"latency_ms": list(map(float, latencies))},
        # The node's own figures (from /diagnostics, means per 1 s window) show where the
        # end-to-end time goes: processing vs waiting (the two-lidar merge, queues).
        "targets": [
            target_row(
                "node end-to-end latency p99",
                "<= 50 ms",
                p99,
                None if (args.quick or p99 is None) else p99 <= 50.0,
                "ms",
            ),
            target_row(
                "node CPU at real-time input", "(reported)", node_cpu_percent, None, "% of one core"
            ),
        ],
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    sys.exit(main())
