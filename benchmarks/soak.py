"""Soak: half an hour (or more) of simulated two-lidar stream, faster than real time.

    python benchmarks/soak.py [--minutes 30] [--quick] [--json OUT.json]

The stream is one cycle repeated with continuous stamps: the simulator's 45 s
``takeoff_landing`` flight (take-off from a pad beside the rig, a loop with a hover,
return and landing) followed by 30 s of the same car park without a drone
(``no_drone``, same seed, so the same static scene). So the drone appears and
disappears every 75 s, 24 times in half an hour.
Both clips are rendered once (cached by ``datasets.simulated``) and replayed with shifted
stamps; frames go through the node's two stages without DDS: :class:`StampMerger`
(clock = stamps) and :class:`StreamingDetector`.

Every 30 s of stream time: process RSS, the detector's state (accumulator voxels,
local-history points, track samples, bytes), the merge queue and the push time. Per
cycle: the evaluator's metrics against the total-station ground truth (detection rate
among the GT samples where the drone was observable - at least 3 drone points in a
frame within 0.1 s - median error) and the estimates published during the drone-free
30 s. Printed: start/warm-up/end figures, growth, and first vs last cycle.
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchlib import bench_main, target_row  # noqa: E402
from datasets import simulated  # noqa: E402

from clusterfilter_ros.core.evaluation import evaluate  # noqa: E402
from clusterfilter_ros.core.frame import AVIA, MID360, Frame, TimedPositions  # noqa: E402
from clusterfilter_ros.core.params import detector_params  # noqa: E402
from clusterfilter_ros.core.streaming import StreamingDetector  # noqa: E402
from clusterfilter_ros.ros.merge import StampMerger  # noqa: E402

COMMAND = "python benchmarks/soak.py"
DRONE_SCENARIO, DRONE_SECONDS = "takeoff_landing", 45.0
GAP_SCENARIO, GAP_SECONDS = "no_drone", 30.0
SAMPLE_EVERY = 30.0  # stream seconds between samples
WARMUP = 180.0  # stream seconds before the "after warm-up" reference sample
MIN_DRONE_POINTS = 3  # drone points in a frame for the drone to count as observable


def _clip(scenario: str, seed: int, seconds: float) -> tuple[list[Frame], list[int], Any]:
    """Frames (stamps from 0), drone points per frame, and the simulation result."""
    sim = simulated(scenario, seed, seconds)
    frames = sim.sequence.frames
    t0 = frames[0].stamp
    shifted = [Frame(f.stamp - t0, f.sensor, f.xyz, f.intensity, f.point_time) for f in frames]
    drone_points = [int(sim.labels[i].sum()) for i in range(len(frames))]
    return shifted, drone_points, (sim, t0)


def run(args: argparse.Namespace) -> dict[str, Any]:
    import psutil

    minutes = 3.0 if args.quick else args.minutes
    stream_seconds = minutes * 60.0
    tic = time.perf_counter()
    drone_frames, drone_counts, (drone_sim, drone_t0) = _clip(
        DRONE_SCENARIO, args.seed, DRONE_SECONDS
    )
    gap_frames, _, _ = _clip(GAP_SCENARIO, args.seed, GAP_SECONDS)
    render_seconds = time.perf_counter() - tic
    cycle = DRONE_SECONDS + GAP_SECONDS
    gt = drone_sim.sequence.ground_truth
    gt_t = gt.stamps - drone_t0
    frame_t = np.array([f.stamp for f in drone_frames])
    seen_t = frame_t[np.array(drone_counts) >= MIN_DRONE_POINTS]
    near = np.searchsorted(seen_t, gt_t)
    lo = np.abs(gt_t - seen_t[np.clip(near - 1, 0, len(seen_t) - 1)])
    hi = np.abs(gt_t - seen_t[np.clip(near, 0, len(seen_t) - 1)])
    observable = np.minimum(lo, hi) <= 0.1 if len(seen_t) else np.zeros(len(gt_t), bool)

    params = detector_params()
    detector = StreamingDetector(params)
    merger = StampMerger((AVIA, MID360), sync_timeout=0.25)
    process = psutil.Process()
    gc.collect()
    samples: list[dict[str, float]] = []
    est_t: list[float] = []
    est_xyz: list[np.ndarray] = []
    push_ms: list[float] = []
    interval_ms: list[float] = []
    max_queue = 0
    next_sample = 0.0
    n_frames = 0
    started = time.perf_counter()
    cycles = int(np.ceil(stream_seconds / cycle))
    for c in range(cycles):
        base = c * cycle
        clip = [(f, 0.0) for f in drone_frames] + [(f, DRONE_SECONDS) for f in gap_frames]
        for frame, offset in clip:
            stamp = base + offset + frame.stamp
            if stamp >= stream_seconds:
                break
            shifted = Frame(stamp, frame.sensor, frame.xyz, frame.intensity, frame.point_time)
            merger.add(shifted, now=stamp)
            max_queue = max(max_queue, len(merger))
            for item in merger.pop_ready(now=stamp):
                t_push = time.perf_counter()
                estimate = detector.push(item.frame)
                ms = (time.perf_counter() - t_push) * 1e3
                push_ms.append(ms)
                interval_ms.append(ms)
                n_frames += 1
                if estimate is not None:
                    est_t.append(estimate.stamp)
                    est_xyz.append(estimate.position)
            if stamp >= next_sample:
                stats = detector.stats()
                samples.append(
                    {
                        "stream_s": stamp,
                        "wall_s": time.perf_counter() - started,
                        "rss_mb": process.memory_info().rss / 1e6,
                        "accumulator_voxels": stats["accumulator_voxels"],
                        "local_points": stats["local_points"],
                        "track_samples": stats["track_samples"],
                        "state_mb": stats["state_bytes"] / 1e6,
                        "merge_queue": len(merger),
                        "push_ms_mean": float(np.mean(interval_ms)) if interval_ms else 0.0,
                        "push_ms_max": float(np.max(interval_ms)) if interval_ms else 0.0,
                    }
                )
                interval_ms = []
                next_sample += SAMPLE_EVERY
    wall = time.perf_counter() - started
    est_t_arr = np.array(est_t)
    est_xyz_arr = np.array(est_xyz).reshape(-1, 3)

    per_cycle = []
    for c in range(cycles):
        base = c * cycle
        end = min(base + DRONE_SECONDS, stream_seconds)
        if end - base < 30.0:
            break
        keep_gt = gt_t < end - base
        cyc_gt = TimedPositions(gt_t[keep_gt] + base, gt.xyz[keep_gt])
        mask = (est_t_arr >= base) & (est_t_arr < end)
        pred = TimedPositions(est_t_arr[mask], est_xyz_arr[mask])
        result = evaluate(pred, cyc_gt, observable=observable[keep_gt])
        gap_lo, gap_hi = base + DRONE_SECONDS + 1.0, min(base + cycle, stream_seconds)
        in_gap = int(((est_t_arr >= gap_lo) & (est_t_arr < gap_hi)).sum())
        per_cycle.append(
            [
                c + 1,
                base / 60.0,
                result.n_pred,
                result.observable_detection_rate,
                result.median_error,
                result.p95_error,
                in_gap,
                max(gap_hi - gap_lo, 0.0) * 20,
            ]
        )

    warm = next((s for s in samples if s["stream_s"] >= WARMUP), samples[-1])
    last = samples[-1]
    after = [s for s in samples if s["stream_s"] >= WARMUP] or samples
    first_half = [s for s in after if s["stream_s"] < (warm["stream_s"] + last["stream_s"]) / 2]
    second_half = [s for s in after if s not in first_half] or after
    growth = {
        key: max(s[key] for s in second_half) / max(max(s[key] for s in first_half or after), 1e-9)
        for key in ("accumulator_voxels", "local_points", "state_mb")
    }
    rss_growth = last["rss_mb"] - warm["rss_mb"]
    first_c, last_c = per_cycle[0], per_cycle[-1]
    print(
        f"[soak] {stream_seconds / 60:.0f} min of stream ({n_frames} frames, {cycles} cycles of "
        f"{cycle:.0f} s) in {wall:.0f} s wall = {stream_seconds / wall:.1f}x real time "
        f"(+{render_seconds:.0f} s to render/load the clips)"
    )
    print(
        f"[soak] RSS {samples[0]['rss_mb']:.0f} MB at start, {warm['rss_mb']:.0f} MB after "
        f"{WARMUP / 60:.0f} min, {last['rss_mb']:.0f} MB at the end (growth after warm-up "
        f"{rss_growth:+.1f} MB, peak {max(s['rss_mb'] for s in samples):.0f} MB)"
    )
    print(
        f"[soak] accumulator {warm['accumulator_voxels']:.0f} -> {last['accumulator_voxels']:.0f}"
        f" voxels (peak {max(s['accumulator_voxels'] for s in samples):.0f}, cap "
        f"{params.max_accumulator_voxels}); local history peak "
        f"{max(s['local_points'] for s in samples):.0f} points (cap {params.max_local_points});"
        f" state peak {max(s['state_mb'] for s in samples):.1f} MB; merge queue <= {max_queue};"
        f" push mean {np.mean(push_ms):.1f} ms, p99 {np.percentile(push_ms, 99):.1f} ms"
    )
    print(
        f"[soak] first cycle: detection {first_c[3]:.2f}, median error {first_c[4]:.2f} m, "
        f"{first_c[6]} estimates in the drone-free gap; last cycle: detection "
        f"{last_c[3]:.2f}, median error {last_c[4]:.2f} m, {last_c[6]} in the gap"
    )
    bounded = all(g <= 1.2 for g in growth.values()) and max_queue <= 4
    return {
        "benchmark": "soak",
        "command": COMMAND,
        "tables": [
            {
                "id": "soak_cycles",
                "title": f"Soak: detection per {cycle:.0f} s cycle ({DRONE_SCENARIO} + "
                f"{GAP_SECONDS:.0f} s without drone)",
                "columns": [
                    "cycle",
                    "starts at (min)",
                    "estimates",
                    "detection (observable GT)",
                    "median error (m)",
                    "p95 error (m)",
                    "estimates in drone-free gap",
                    "gap frames",
                ],
                "rows": per_cycle,
            },
            {
                "id": "soak_state",
                "title": f"Soak: state every {SAMPLE_EVERY:.0f} s of stream",
                "columns": [
                    "stream (min)",
                    "wall (s)",
                    "RSS (MB)",
                    "accumulator voxels",
                    "local points",
                    "track samples",
                    "state (MB)",
                    "merge queue",
                    "push mean (ms)",
                    "push max (ms)",
                ],
                "rows": [
                    [
                        s["stream_s"] / 60.0,
                        s["wall_s"],
                        s["rss_mb"],
                        s["accumulator_voxels"],
                        s["local_points"],
                        s["track_samples"],
                        s["state_mb"],
                        s["merge_queue"],
                        s["push_ms_mean"],
                        s["push_ms_max"],
                    ]
                    for s in samples[:: max(1, len(samples) // 30)]
                ],
            },
        ],
        "series": {"samples": samples, "cycles": per_cycle},
        "targets": [
            target_row("soak stream length", ">= 30 min", stream_seconds / 60.0, minutes >= 30),
            target_row(
                "state growth after warm-up (2nd half peak / 1st half peak)",
                "<= 1.2",
                max(growth.values()),
                bounded,
            ),
            target_row("RSS growth after warm-up", "< 50 MB", rss_growth, rss_growth < 50, "MB"),
            target_row(
                "detection in the last cycle vs the first",
                ">= first - 0.05",
                last_c[3],
                bool(last_c[3] >= first_c[3] - 0.05),
            ),
            target_row(
                "faster than real time", "> 1x", stream_seconds / wall, wall < stream_seconds
            ),
        ],
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--minutes", type=float, default=30.0, help="stream minutes (30)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed (0)")


def main() -> None:
    """Run the soak and print its figures (``--quick``: 3 minutes)."""
    bench_main("soak", run, add_arguments, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
