"""Detector timings and memory: offline 20 s, streaming per frame, state over a 2-minute stream.

    python benchmarks/bench_detector.py [--quick] [--json OUT.json] [--scenario NAME]

- ``offline``: ``detect_offline`` wall time on a simulated 20 s sequence (both lidars,
  full rate), best of 3 runs, on one core.
- ``streaming``: ``StreamingDetector.push`` time for every frame of the same sequence
  at the real input rate of both lidars (10 Hz each), re-clustering included:
  median / mean / p99 / max, and the mean re-clustering time.
- ``memory``: the sequence looped into a 2-minute stream (stamps shifted per loop, so
  the static scene keeps accumulating): the detector's own state size
  (``stats()["state_bytes"]``) and the process RSS every 5 s of stream time; flat
  means the last minute's maximum is within 10% of the first minute's (after warm-up).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchlib import bench_main, percentiles, target_row  # noqa: E402
from datasets import simulated, stream  # noqa: E402


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default="takeoff_landing", help="simulated scenario")
    parser.add_argument("--seed", type=int, default=0)


def run(args: argparse.Namespace) -> dict[str, Any]:
    import psutil

    from clusterfilter_ros.core.offline import detect_offline
    from clusterfilter_ros.core.streaming import StreamingDetector

    duration = 5.0 if args.quick else 20.0
    sim = simulated(args.scenario, args.seed, duration)
    frames = sim.sequence.frames
    points = sum(len(f) for f in frames)

    # Offline: best of 3.
    offline_s = []
    for _ in range(1 if args.quick else 3):
        tic = time.perf_counter()
        detect_offline(frames)
        offline_s.append(time.perf_counter() - tic)

    # Streaming at the real rate: every frame's push time.
    det = StreamingDetector()
    push_ms = []
    for f in frames:
        tic = time.perf_counter()
        det.push(f)
        push_ms.append((time.perf_counter() - tic) * 1e3)
    push_ms = np.asarray(push_ms)
    st = det.stats()
    pct = percentiles(push_ms, (50, 99))

    # Memory over a long stream.
    long_seconds = 20.0 if args.quick else 120.0
    det = StreamingDetector()
    proc = psutil.Process()
    t0 = frames[0].stamp
    mem_t, state_b, rss_b, voxels = [], [], [], []
    next_sample = 0.0
    for f in stream(frames, 1.0, long_seconds):
        det.push(f)
        if f.stamp - t0 >= next_sample:
            s = det.stats()
            mem_t.append(f.stamp - t0)
            state_b.append(s["state_bytes"])
            rss_b.append(proc.memory_info().rss)
            voxels.append(s["accumulator_voxels"])
            next_sample += 5.0
    mem_t = np.asarray(mem_t)
    state_b = np.asarray(state_b)
    rss_b = np.asarray(rss_b)
    half = long_seconds / 2
    first = (mem_t >= 25.0) & (mem_t < half) if not args.quick else mem_t < half
    last = mem_t >= half
    state_ratio = float(state_b[last].max() / max(state_b[first].max(), 1.0))
    rss_ratio = float(rss_b[last].max() / max(rss_b[first].max(), 1.0))

    rows_time = [
        ["offline detect (s), best of runs", min(offline_s)],
        ["streaming push median (ms)", pct["p50"]],
        ["streaming push mean (ms)", float(push_ms.mean())],
        ["streaming push p99 (ms)", pct["p99"]],
        ["streaming push max (ms)", float(push_ms.max())],
        ["re-clustering mean (ms)", st["mean_recluster_ms"]],
        ["frames / points in the sequence", f"{len(frames)} / {points}"],
    ]
    rows_mem = [
        [f"{t:.0f}", b / 1e6, r / 1e6, v]
        for t, b, r, v in zip(mem_t, state_b, rss_b, voxels, strict=True)
    ]
    return {
        "command": "python benchmarks/bench_detector.py",
        "tables": [
            {
                "id": "detector-time",
                "title": f"Detector time, simulated '{args.scenario}' {duration:g} s, seed "
                f"{args.seed}",
                "columns": ["measure", "value"],
                "rows": rows_time,
            },
            {
                "id": "detector-memory",
                "title": f"Streaming state over a {long_seconds:g} s stream",
                "columns": ["stream time s", "state MB", "process RSS MB", "persistence voxels"],
                "rows": rows_mem,
            },
        ],
        "series": {
            "push_ms": push_ms.tolist(),
            "memory_t": mem_t.tolist(),
            "state_bytes": state_b.tolist(),
            "rss_bytes": rss_b.tolist(),
        },
        "targets": [
            target_row(
                "offline 20 s sequence", "<= 2 s", min(offline_s), min(offline_s) <= 2.0, "s"
            ),
            target_row(
                "streaming median per frame", "<= 10 ms", pct["p50"], pct["p50"] <= 10, "ms"
            ),
            target_row(
                "state flat over 2 min (last/first max)",
                "<= 1.1",
                state_ratio,
                state_ratio <= 1.1,
            ),
            target_row(
                "RSS flat over 2 min (last/first max)", "<= 1.1", rss_ratio, rss_ratio <= 1.1
            ),
        ],
    }


if __name__ == "__main__":
    bench_main("detector", run, add_arguments, __doc__.splitlines()[0])
