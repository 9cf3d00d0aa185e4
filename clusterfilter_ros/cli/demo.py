"""``clusterfilter demo``: simulate, detect over DDS in separate processes, evaluate, plot.

1. simulate a scenario into OUT/sequence (a challenge-format folder with ground truth);
2. start the detector node, a recorder of ``/uav/pose``, one of ``/uav/pose_delayed``
   (the ``report_lag`` output, ``--report-lag`` seconds late) and a replay of the folder
   as processes on loopback DDS with one random ROS domain for this run;
3. evaluate the recorded poses against the ground truth, print the metrics of both
   outputs, write OUT/metrics.json and the trajectory plot OUT/trajectory.png.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

from clusterfilter_ros.errors import ClusterfilterError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="simulate a scene, run node + replay + recorder over DDS, evaluate and plot",
        description="End-to-end demo: simulate a scenario, start the detector node, replay "
        "the simulated lidars into it and record /uav/pose and /uav/pose_delayed (separate "
        "processes over loopback DDS), then evaluate against ground truth and plot.",
    )
    p.add_argument("--scenario", default="default", help="simulator scenario (default: default)")
    p.add_argument("--seed", type=int, default=0, help="simulator seed (default: 0)")
    p.add_argument("--out", help="output folder (default: a new temporary folder)")
    p.add_argument(
        "--duration", type=float, help="seconds to simulate (default: the scenario's length)"
    )
    p.add_argument(
        "--rate", type=float, default=1.0, help="replay speed, 1 = real time (default: 1)"
    )
    p.add_argument("--params-file", help="detector parameters (default: config/detector.yaml)")
    p.add_argument(
        "--report-lag",
        type=float,
        default=3.0,
        help="also record /uav/pose_delayed with this report_lag (s); 0: not (default: 3)",
    )
    p.set_defaults(func=run)


def _fmt(value: object) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.3f}"
    return str(value)


def run(args: argparse.Namespace) -> int:
    import tempfile

    import numpy as np

    from clusterfilter_ros.core.evaluation import evaluate
    from clusterfilter_ros.io.dataset import open_input, write_output
    from clusterfilter_ros.io.groundtruth import read_positions_csv
    from clusterfilter_ros.plots import plot_evaluation
    from clusterfilter_ros.resources import config_file
    from clusterfilter_ros.ros import processes
    from clusterfilter_ros.sim.scenarios import simulate

    if not args.rate > 0:
        raise ClusterfilterError(f"--rate must be > 0 for the demo, got {args.rate}")
    if not 0 <= args.report_lag <= 60:
        raise ClusterfilterError(f"--report-lag must be within [0, 60], got {args.report_lag}")
    started = time.monotonic()
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="clusterfilter-demo-"))
    out.mkdir(parents=True, exist_ok=True)
    params_file = Path(args.params_file) if args.params_file else config_file("detector.yaml")
    if not params_file.is_file():
        raise ClusterfilterError(f"params file {params_file} does not exist")

    print(f"demo: simulating scenario '{args.scenario}' (seed {args.seed}) ...", flush=True)
    if args.duration is not None and not args.duration > 0:
        raise ClusterfilterError(f"--duration must be > 0, got {args.duration}")
    simulated = simulate(args.scenario, seed=args.seed, duration=args.duration)
    folder = write_output(simulated.sequence, out / "sequence", fmt="mmaud", overwrite=True)
    sequence = open_input(folder)
    if sequence.ground_truth is None or not len(sequence.ground_truth):
        raise ClusterfilterError(f"scenario '{args.scenario}' has no drone to evaluate against")
    n_frames = len(sequence.frames)
    span = sequence.end - sequence.start
    offset = [float(v) for v in np.asarray(simulated.prism_offset).reshape(3)]
    print(
        f"demo: {n_frames} lidar frames over {span:.1f} s written to {folder} "
        f"({time.monotonic() - started:.1f} s)",
        flush=True,
    )

    env = processes.demo_environment()
    logs = out / "logs"
    estimates_csv = out / "estimates.csv"
    late_csv = out / "estimates_late.csv"
    points_npy = out / "drone_points.npy"
    bag = out / "estimates_bag"
    if bag.exists():
        shutil.rmtree(bag)
    print(
        f"demo: ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}, DDS on loopback "
        f"({env['FASTRTPS_DEFAULT_PROFILES_FILE']}); logs in {logs}",
        flush=True,
    )
    # The ground truth marks a prism mounted above the drone; the detector is told the
    # mount offset (target_offset), as a user of the real rig would be.
    detector = processes.start(
        "detector",
        processes.cli_command(
            "detector",
            "--params-file",
            str(params_file),
            "-p",
            "target_offset=" + ",".join(repr(v) for v in offset),
            "-p",
            f"report_lag={args.report_lag!r}",
        ),
        env,
        logs,
    )
    replay_timeout = span / args.rate + 90.0
    recorder = processes.start(
        "recorder",
        processes.cli_command(
            "record",
            str(estimates_csv),
            "--points",
            str(points_npy),
            "--bag",
            str(bag),
            "--until-frames",
            str(n_frames),
            "--timeout",
            f"{replay_timeout + 30.0:.0f}",
        ),
        env,
        logs,
    )
    children = [detector, recorder]
    late_recorder = None
    if args.report_lag > 0:
        late_recorder = processes.start(
            "late_recorder",
            processes.cli_command(
                "record",
                str(late_csv),
                "--topic",
                "/uav/pose_delayed",
                "--duration",  # a bound only: stopped after the replay (below)
                f"{replay_timeout + 60.0:.0f}",
            ),
            env,
            logs,
        )
        children.append(late_recorder)
    try:
        # Replay only once the recorders hear the detector, so no pose is missed.
        for rec in filter(None, (recorder, late_recorder)):
            if not processes.wait_for_log(rec, "record: matched", 60.0):
                raise ClusterfilterError(
                    f"the {rec.name} never saw the detector:\n"
                    + rec.log_tail()
                    + "\n--- detector log ---\n"
                    + detector.log_tail()
                )
        replay = processes.start(
            "replay",
            processes.cli_command(
                "replay", str(folder), "--rate", repr(args.rate), "--wait-for", "/uav/pose"
            ),
            env,
            logs,
        )
        children.append(replay)
        print(f"demo: replaying at rate {args.rate:g} (about {span / args.rate:.0f} s) ...")
        code = replay.wait(replay_timeout)
        if code != 0:
            raise ClusterfilterError(
                f"replay {'timed out' if code is None else f'exited with {code}'}:\n"
                + replay.log_tail()
                + "\n--- detector log ---\n"
                + detector.log_tail()
            )
        replay_done = time.monotonic()
        code = recorder.wait(60.0)
        if code is None:
            print("demo: recorder still waiting for the detector; stopping it", flush=True)
            code = recorder.interrupt()
        if code != 0 or not estimates_csv.is_file():
            raise ClusterfilterError(f"recorder exited with {code}:\n{recorder.log_tail()}")
        drain = time.monotonic() - replay_done
        if late_recorder is not None:
            # The detector estimates the last report_lag seconds of frames once its input
            # has been quiet for report_lag (at least 1) s, checked every second.
            time.sleep(max(args.report_lag, 1.0) + 2.5)
            code = late_recorder.interrupt()
            if code != 0 or not late_csv.is_file():
                raise ClusterfilterError(
                    f"late recorder exited with {code}:\n{late_recorder.log_tail()}"
                )
        detector_code = detector.interrupt()
        if detector_code != 0:
            print(
                f"demo: warning: detector exited with {detector_code}:\n{detector.log_tail()}",
                file=sys.stderr,
            )
    finally:
        for child in children:
            if child.running():
                child.interrupt(timeout=5.0)

    pred = read_positions_csv(estimates_csv)
    gt = sequence.ground_truth
    result = evaluate(pred, gt, duration=span)
    metrics = result.as_dict()
    late_metrics = None
    late_pred = None
    if late_recorder is not None:
        late_pred = read_positions_csv(late_csv)
        late_metrics = evaluate(late_pred, gt, duration=span).as_dict()
        late_metrics["poses"] = len(late_pred)
    metrics_path = out / "metrics.json"
    from clusterfilter_ros.io.atomic import atomic_write_text

    drone_points = np.load(points_npy) if points_npy.is_file() else None
    summary = {
        "scenario": args.scenario,
        "seed": args.seed,
        "replay_rate": args.rate,
        "frames": n_frames,
        "poses": len(pred),
        "target_offset": offset,
        "detector_drain_seconds": round(drain, 3),
        "metrics": metrics,
        "report_lag": args.report_lag,
        "late_metrics": late_metrics,
    }
    atomic_write_text(metrics_path, json.dumps(summary, indent=2) + "\n")
    plot_path = plot_evaluation(
        gt,
        pred,
        out / "trajectory.png",
        drone_points=drone_points,
        title=f"clusterfilter demo: scenario {args.scenario}, seed {args.seed}",
        late=late_pred,
        late_label=f"{args.report_lag:g} s late",
    )
    print(f"demo: {len(pred)} poses recorded from {n_frames} frames")
    for key in (
        "coverage",
        "detection_rate",
        "mean_error",
        "rmse",
        "median_error",
        "p95_error",
        "mse",
        "false_alarm_seconds",
    ):
        print(f"  {key:>20}: {_fmt(metrics.get(key))}")
    if late_metrics is not None:
        print(
            f"demo: {late_metrics['poses']} poses {args.report_lag:g} s late "
            "(/uav/pose_delayed: every frame again, from the returns on both sides of it)"
        )
        for key in ("coverage", "detection_rate", "rmse"):
            print(f"  {key:>20}: {_fmt(late_metrics.get(key))}")
    print("demo: outputs")
    for label, path in (
        ("simulated sequence", folder),
        ("estimates (CSV)", estimates_csv),
        *([("late estimates (CSV)", late_csv)] if late_metrics is not None else []),
        ("estimates (ROS 2 bag)", bag),
        ("drone points", points_npy),
        ("metrics", metrics_path),
        ("trajectory plot", plot_path),
        ("process logs", logs),
    ):
        print(f"  {label:>22}: {path}")
    print(f"demo: done in {time.monotonic() - started:.1f} s")
    return 0
