"""Re-clustering inside ``push`` vs on a background thread, frames paced at real time.

A re-clustering (every ``recluster_period``, 0.5 s) takes tens of milliseconds, and
inside ``push`` the frame that triggers it, and every frame queued behind it, waits that
long. ``StreamingDetector(background=True)`` (the node's ``recluster_in_background``)
runs it on a worker thread instead; frames meanwhile are tracked with the current track.
This pushes a simulated recording's frames at their real rate (sleeping until each
frame's stamp, as a driver would deliver them) through both, and prints per mode:

- the wall time from a frame's due time to the end of its ``push`` (waiting behind an
  earlier frame included): p50 / p95 / p99 / max;
- the accuracy of the estimates against the ground truth (the same evaluation as
  ``detector_accuracy.py``: detection over the observable time, RMSE).

    .venv/bin/python benchmarks/bench_background_recluster.py --scenario avia_only \\
        --seeds 100 101 [--rate 1]

Each (seed, mode) takes the recording's length in wall time divided by ``--rate``.

With ``--full-rows-rates 5 7 10`` it measures throughput instead: the benchmark suite's
worst case (``bench_core.py`` "full rows": the ``default`` seed 1 sequence with every
MMAUD row a return, looped and time-compressed by the rate) pushed as fast as possible,
and the wall time per second of stream after the 20 s warm-up, both modes. Below 1 the
detector keeps up. The background worker overlaps with the frames only where numpy and
the clusterer release the GIL.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from clusterfilter_ros.core.params import detector_params
from clusterfilter_ros.core.streaming import StreamingDetector

sys.path.insert(0, str(Path(__file__).resolve().parent))
from detector_accuracy import (  # noqa: E402
    SIM_CACHE,
    dedupe,
    estimates_to_positions,
    evaluate_on_sim,
    load_sim,
    sim_params,
)

MODES = {"in push": False, "background": True}


def paced_run(sim, background: bool, rate: float) -> tuple[np.ndarray, list, dict]:
    """Push every frame at its stamp's wall time; (latency ms per frame, estimates, stats)."""
    params = sim_params(sim)
    frames = sim.sequence.frames
    detector = StreamingDetector(params, background=background)
    latency = np.empty(len(frames))
    estimates = []
    t0 = frames[0].stamp
    start = time.perf_counter()
    try:
        for i, frame in enumerate(frames):
            due = start + (frame.stamp - t0) / rate
            pause = due - time.perf_counter()
            if pause > 0:
                time.sleep(pause)
            estimate = detector.push(frame)
            latency[i] = (time.perf_counter() - due) * 1e3
            if estimate is not None:
                estimates.append(estimate)
        stats = detector.stats()
    finally:
        detector.close()
    return latency, estimates, stats


def full_rows_load(rate: float, background: bool, warmup: float = 20.0, span: float = 5.0):
    """Wall seconds per stream second for the full-row stream at ``rate`` (after warm-up)."""
    from datasets import full_row_frames, simulated, stream

    params = detector_params()
    frames = full_row_frames(
        simulated("default", 1, 20.0).sequence.frames, min_z=params.mid360_min_z
    )
    detector = StreamingDetector(params, background=background)
    first = started = None
    try:
        for frame in stream(frames, rate, warmup + span):
            first = frame.stamp if first is None else first
            if started is None and frame.stamp - first >= warmup:
                started = time.perf_counter()
            detector.push(frame)
        detector.finish_recluster()
        assert started is not None
        return (time.perf_counter() - started) / span
    finally:
        detector.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="avia_only")
    ap.add_argument("--seeds", nargs="+", type=int, default=[100])
    ap.add_argument("--rate", type=float, default=1.0, help="replay speed (1 = real time)")
    ap.add_argument("--duration", type=float, help="simulate this many seconds (default: all)")
    ap.add_argument("--cache", type=Path, default=SIM_CACHE)
    ap.add_argument(
        "--full-rows-rates",
        nargs="+",
        type=float,
        metavar="RATE",
        help="measure full-row throughput at these multiples of real time instead",
    )
    args = ap.parse_args(argv)
    if args.full_rows_rates:
        print("| full rows at | mode | processing s per stream s | keeps up |")
        print("|---|---|---|---|")
        for rate in args.full_rows_rates:
            for mode, background in MODES.items():
                load = full_rows_load(rate, background)
                print(f"| {rate:g}x | {mode} | {load:.2f} | {'yes' if load < 1 else 'no'} |")
        return 0
    header = (
        "| run | mode | frames | latency p50 / p95 / p99 / max ms | re-clusterings | "
        "mean re-clustering ms | estimates | detection % | RMSE m |"
    )
    print(header)
    print("|" + "---|" * header.count(" | ") + "---|")
    for seed in args.seeds:
        sim = load_sim(args.scenario, seed, args.cache, args.duration)
        for mode, background in MODES.items():
            latency, estimates, stats = paced_run(sim, background, args.rate)
            res = evaluate_on_sim(sim, dedupe(estimates_to_positions(estimates))).as_dict()
            p50, p95, p99 = np.percentile(latency, [50, 95, 99])
            det = res["observable_detection_rate"]
            rmse = res["rmse"]
            print(
                f"| {args.scenario} s{seed} | {mode} | {len(latency)} | "
                f"{p50:.1f} / {p95:.1f} / {p99:.1f} / {latency.max():.1f} | "
                f"{stats['reclusters']:.0f} | {stats['mean_recluster_ms']:.1f} | "
                f"{len(estimates)} | {100 * det:.1f} | "
                + ("n/a" if rmse is None or not np.isfinite(rmse) else f"{rmse:.3f}")
                + " |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
