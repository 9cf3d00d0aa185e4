"""Simulator benchmark: generation speed, per-frame statistics against MMAUD, drone hits.

    python benchmarks/bench_simulate.py [--quick] [--json OUT.json]

Parts:

- ``speed``: time to generate the 20 s ``default`` scenario (wall and CPU time of this
  process, one core), per-frame render time per sensor; target < 10 s of CPU time.
- ``stats``: points per frame of each lidar against the real challenge files (Mid360
  19,968/20,064 rows with ~3.9k-4.4k points; Avia 24,000 rows with 0-178 points) for
  every scenario's first seconds.
- ``hits``: mean drone points per frame against range for each drone model (Mid360 at
  15 deg elevation, Avia straight overhead).
- ``stream``: resident memory while streaming a long ``long_mixed`` run frame by frame.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchlib import bench_main, percentiles, profile_call, target_row  # noqa: E402

from clusterfilter_ros.core.frame import AVIA, MID360  # noqa: E402
from clusterfilter_ros.sim.actors import DRONE_MODELS  # noqa: E402
from clusterfilter_ros.sim.analysis import drone_hits_per_frame  # noqa: E402
from clusterfilter_ros.sim.scenarios import SCENARIOS, Simulation, simulate  # noqa: E402

COMMAND = "python benchmarks/bench_simulate.py"


def _speed(duration: float) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Render the default scenario frame by frame (what ``simulate`` does), timing each."""
    per_frame: dict[str, list[float]] = {MID360: [], AVIA: []}
    wall0, cpu0 = time.perf_counter(), time.process_time()
    sim = Simulation("default", seed=0, duration=duration)
    sim.ground_truth()
    sim.drone_truth()
    frames = sim.iter_frames()
    while True:
        t = time.process_time()
        sf = next(frames, None)
        if sf is None:
            break
        per_frame[sf.frame.sensor].append((time.process_time() - t) * 1e3)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    rows = [
        {"what": f"default scenario, {duration:g} s, both lidars", "wall_s": wall, "cpu_s": cpu}
    ]
    series = {
        "duration_s": duration,
        "wall_s": wall,
        "cpu_s": cpu,
        "frame_ms": {k: percentiles(v) for k, v in per_frame.items()},
    }
    return series, rows


def _stats(seconds: float) -> list[list[Any]]:
    rows = []
    for name in SCENARIOS:
        if name.startswith("model_"):
            continue
        counts: dict[str, list[int]] = {MID360: [], AVIA: []}
        sim = Simulation(name, seed=0, duration=seconds)
        drone = {MID360: 0, AVIA: 0}
        for sf in sim.iter_frames():
            counts[sf.frame.sensor].append(len(sf.frame))
            drone[sf.frame.sensor] += int(sf.drone_mask.sum())
        m, a = np.array(counts[MID360]), np.array(counts[AVIA])
        rows.append(
            [
                name,
                int(m.min()),
                int(np.median(m)),
                int(m.max()),
                int(a.min()),
                int(np.median(a)),
                int(np.percentile(a, 90)),
                int(a.max()),
                drone[MID360] / len(m),
                drone[AVIA] / len(a),
            ]
        )
    rows.append(["real MMAUD sequence", 3900, "-", 4400, 0, "-", "-", 178, "-", "-"])
    return rows


def _hits(frames: int) -> list[list[Any]]:
    rows = []
    for model in DRONE_MODELS:
        row: list[Any] = [model]
        for distance in (10.0, 25.0, 50.0, 70.0):
            row.append(drone_hits_per_frame(model, distance, 15.0, frames=frames)[MID360])
        for distance in (50.0, 100.0, 150.0):
            row.append(drone_hits_per_frame(model, distance, 85.0, frames=frames)[AVIA])
        rows.append(row)
    return rows


def _stream(seconds: float) -> dict[str, Any]:
    import psutil

    proc = psutil.Process()
    sim = Simulation("long_mixed", seed=0, duration=seconds)
    rss = []
    n = 0
    t0 = time.perf_counter()
    for n, _ in enumerate(sim.iter_frames(), start=1):
        if n % 50 == 0:
            rss.append(proc.memory_info().rss / 2**20)
    wall = time.perf_counter() - t0
    return {
        "seconds": seconds,
        "frames": n,
        "wall_s": wall,
        "rss_mb_first": rss[0] if rss else float("nan"),
        "rss_mb_last": rss[-1] if rss else float("nan"),
        "rss_mb_max": max(rss) if rss else float("nan"),
    }


def run(args: argparse.Namespace) -> dict[str, Any]:
    duration = 4.0 if args.quick else 20.0
    speed, speed_rows = _speed(duration)
    stats_rows = _stats(1.0 if args.quick else 3.0)
    hit_rows = _hits(5 if args.quick else 20)
    stream = _stream(10.0 if args.quick else 60.0)
    _, profile = profile_call(lambda: simulate("default", seed=1, duration=2.0))
    scaled_cpu = speed["cpu_s"] * 20.0 / duration
    tables = [
        {
            "id": "sim_speed",
            "title": f"Simulator speed ({duration:g} s of the default scenario, one core)",
            "columns": ["what", "wall (s)", "CPU (s)"],
            "rows": [[r["what"], r["wall_s"], r["cpu_s"]] for r in speed_rows]
            + [
                [
                    f"Mid360 frame, p50/p95 ms: {speed['frame_ms'][MID360]['p50']:.1f}/"
                    f"{speed['frame_ms'][MID360]['p95']:.1f}",
                    None,
                    None,
                ],
                [
                    f"Avia frame, p50/p95 ms: {speed['frame_ms'][AVIA]['p50']:.1f}/"
                    f"{speed['frame_ms'][AVIA]['p95']:.1f}",
                    None,
                    None,
                ],
            ],
        },
        {
            "id": "sim_stats",
            "title": "Points per frame by scenario (first seconds, seed 0) vs the real files",
            "columns": [
                "scenario",
                "Mid360 min",
                "Mid360 median",
                "Mid360 max",
                "Avia min",
                "Avia median",
                "Avia p90",
                "Avia max",
                "drone pts/frame Mid360",
                "drone pts/frame Avia",
            ],
            "rows": stats_rows,
        },
        {
            "id": "sim_hits",
            "title": "Mean drone points per frame vs range (hovering, car park)",
            "columns": [
                "drone",
                "Mid360 10 m",
                "Mid360 25 m",
                "Mid360 50 m",
                "Mid360 70 m",
                "Avia 50 m up",
                "Avia 100 m up",
                "Avia 150 m up",
            ],
            "rows": hit_rows,
        },
        {
            "id": "sim_stream",
            "title": "Streaming long_mixed frame by frame",
            "columns": ["simulated s", "frames", "wall (s)", "RSS first (MB)", "RSS last (MB)"],
            "rows": [
                [
                    stream["seconds"],
                    stream["frames"],
                    stream["wall_s"],
                    stream["rss_mb_first"],
                    stream["rss_mb_last"],
                ]
            ],
        },
    ]
    mid_median = float(np.median([r[2] for r in stats_rows[:-1]]))
    targets = [
        target_row("20 s sequence CPU time", "< 10 s", scaled_cpu, scaled_cpu < 10.0, "s"),
        target_row(
            "Mid360 median points/frame",
            "3,900-4,400",
            mid_median,
            3900 <= mid_median <= 4400,
        ),
    ]
    return {
        "benchmark": "simulate",
        "command": COMMAND,
        "tables": tables,
        "series": {"speed": speed, "stream": stream},
        "targets": targets,
        "profiles": {"simulate_default_2s": profile},
    }


if __name__ == "__main__":
    bench_main("simulate", run, description=__doc__.splitlines()[0])
