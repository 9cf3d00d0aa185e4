"""Memory of the streaming detector over a long simulated stream at full rate.

    python benchmarks/bench_memory.py [--quick] [--minutes 60] [--budget SECONDS] [--json F]

Frames of both lidars (simulated: the 2-minute ``long_mixed`` flight, take-off, passes,
hover, out of range and back, landing, followed by the 20 s ``default`` flight, where
the drone arrives and leaves) are generated once and looped with shifted stamps, so
the stream has the drone appearing and disappearing and generation cost does not
dominate. They are pushed through one ``StreamingDetector`` as fast as it takes them
(the stamps say full rate, 10 Hz per lidar). Every 10 s of stream time the process RSS
(psutil) and the detector's own state size are sampled.

The run stops after ``--minutes`` of stream time or ``--budget`` wall seconds,
whichever comes first (budget 0 = no limit), and says how far it got. Reported: RSS
after warm-up (minute 5) and at the end, growth between them, peak RSS.
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
from datasets import simulated, stream  # noqa: E402

from clusterfilter_ros.core.frame import Frame  # noqa: E402
from clusterfilter_ros.core.params import detector_params  # noqa: E402

COMMAND = "python benchmarks/bench_memory.py"
SAMPLE_EVERY = 10.0  # stream seconds between RSS samples
WARMUP_MINUTE = 5.0


def loop_source(quick: bool) -> tuple[list[Frame], str]:
    """Frames of one loop of the stream, in stamp order, and a description."""
    if quick:
        parts = [("default", 1, 4.0)]
    else:
        parts = [("long_mixed", 2, 120.0), ("default", 1, 20.0)]
    frames: list[Frame] = []
    offset_to = None
    for scenario, seed, duration in parts:
        seq = simulated(scenario, seed, duration).sequence
        src = sorted(seq.frames, key=lambda f: f.stamp)
        if offset_to is None:
            shift = 0.0
        else:
            shift = offset_to - src[0].stamp
        for f in src:
            frames.append(Frame(f.stamp + shift, f.sensor, f.xyz, f.intensity, f.point_time))
        offset_to = frames[-1].stamp + 0.1
    text = " + ".join(f"{s} (seed {seed}, {d:g} s)" for s, seed, d in parts)
    return frames, text


def run(args: argparse.Namespace) -> dict[str, Any]:
    import psutil

    from clusterfilter_ros.core.streaming import StreamingDetector

    quick = args.quick
    minutes = 0.25 if quick else args.minutes
    budget = 8.0 if quick else args.budget
    frames, source = loop_source(quick)
    input_mb = (
        sum(
            f.xyz.nbytes
            + (f.intensity.nbytes if f.intensity is not None else 0)
            + (f.point_time.nbytes if f.point_time is not None else 0)
            for f in frames
        )
        / 2**20
    )
    process = psutil.Process()
    detector = StreamingDetector(detector_params())
    gc.collect()
    rss0 = process.memory_info().rss / 2**20

    samples: list[dict[str, float]] = []
    t0 = None
    next_sample = 0.0
    pushes = 0
    push_seconds = 0.0
    wall0 = time.perf_counter()
    for frame in stream(frames, 1.0, minutes * 60.0):
        if t0 is None:
            t0 = frame.stamp
        rel = frame.stamp - t0
        if rel >= next_sample:
            st = detector.stats()
            samples.append(
                {
                    "minute": rel / 60.0,
                    "rss_mb": process.memory_info().rss / 2**20,
                    "state_mb": st["state_bytes"] / 2**20,
                    "accumulator_voxels": st["accumulator_voxels"],
                    "local_points": st["local_points"],
                    "wall_s": time.perf_counter() - wall0,
                }
            )
            next_sample += SAMPLE_EVERY
            if budget and time.perf_counter() - wall0 > budget:
                break
        tic = time.perf_counter()
        detector.push(frame)
        push_seconds += time.perf_counter() - tic
        pushes += 1
    wall = time.perf_counter() - wall0
    st = detector.stats()
    samples.append(
        {
            "minute": (frame.stamp - t0) / 60.0 if t0 is not None else 0.0,
            "rss_mb": process.memory_info().rss / 2**20,
            "state_mb": st["state_bytes"] / 2**20,
            "accumulator_voxels": st["accumulator_voxels"],
            "local_points": st["local_points"],
            "wall_s": wall,
        }
    )
    minute = np.array([s["minute"] for s in samples])
    rss = np.array([s["rss_mb"] for s in samples])
    state = np.array([s["state_mb"] for s in samples])
    covered = float(minute[-1])
    warm_minute = min(WARMUP_MINUTE, covered / 2) if covered < 2 * WARMUP_MINUTE else WARMUP_MINUTE
    i_warm = int(np.argmin(np.abs(minute - warm_minute)))
    rss_warm, rss_end = float(rss[i_warm]), float(rss[-1])
    growth = (rss_end - rss_warm) / rss_warm
    peak = float(rss.max())
    full = covered >= minutes - 0.05
    rows = [
        [
            source,
            covered,
            pushes,
            wall,
            push_seconds / max(covered * 60.0, 1e-9),
            input_mb,
            rss0,
            float(minute[i_warm]),
            rss_warm,
            rss_end,
            growth * 100.0,
            peak,
            float(state[i_warm]),
            float(state[-1]),
        ]
    ]
    note = (
        f"Stream of {covered:.1f} min ({pushes:,} frames) pushed as fast as the detector takes "
        f"them; RSS sampled every {SAMPLE_EVERY:g} s of stream time. The RSS includes the "
        f"pre-generated input frames the benchmark holds ({input_mb:.0f} MB, loaded before "
        f"'RSS at start'), which a node would not hold. "
    )
    if not full:
        note += (
            f"Stopped by the wall-time budget ({budget:g} s) before {minutes:g} min: the "
            f"growth is measured from minute {minute[i_warm]:.1f} to minute {covered:.1f}."
        )
    measured_to = f"minute {minute[i_warm]:.0f} -> {covered:.0f}"
    targets = [
        target_row("peak RSS over the stream", "<= 500 MB", peak, peak <= 500.0, "MB"),
        target_row(
            f"RSS growth after warm-up ({measured_to})",
            "< 10% (minute 5 -> 60)",
            growth * 100.0,
            (growth < 0.10) if full and covered >= 59.9 else None,
            "%" + ("" if full and covered >= 59.9 else " (not the full hour)"),
        ),
    ]
    return {
        "command": f"{COMMAND} --minutes {minutes:g} --budget {budget:g}"
        + (" --quick" if quick else ""),
        "tables": [
            {
                "id": f"memory{args.table_suffix}",
                "title": f"Streaming detector memory over a {covered:.3g}-minute stream",
                "columns": [
                    "stream",
                    "minutes covered",
                    "frames",
                    "wall s",
                    "processing s per stream s",
                    "input frames held MB",
                    "RSS at start MB",
                    "warm-up minute",
                    "RSS after warm-up MB",
                    "RSS at end MB",
                    "growth %",
                    "peak RSS MB",
                    "detector state after warm-up MB",
                    "detector state at end MB",
                ],
                "rows": rows,
                "note": note,
            }
        ],
        "series": {
            "minute": minute.tolist(),
            "rss_mb": rss.tolist(),
            "state_mb": state.tolist(),
            "accumulator_voxels": [s["accumulator_voxels"] for s in samples],
        },
        "targets": targets,
    }


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--minutes", type=float, default=60.0, help="stream minutes")
    parser.add_argument(
        "--budget", type=float, default=300.0, help="wall seconds allowed (0 = no limit)"
    )
    parser.add_argument("--table-suffix", default="", help="table id suffix (e.g. _1h)")


if __name__ == "__main__":
    bench_main("memory", run, _add_arguments, __doc__.split("\n\n")[0])
