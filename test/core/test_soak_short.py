"""Short soak: minutes of two-lidar stream, faster than real time, with a drone that
comes and goes. The state must stay bounded and the detection at the end must be as
good as at the start.

The stream goes through the same two stages as in the node (ROS-free):
:class:`StampMerger` (stamp-ordered merge, a synthetic clock equal to the stamps) and
:class:`StreamingDetector`. Frames are generated on the fly (a fixed car-park-like
static cloud resampled every Mid360 frame, sparse Avia sky noise, a drone blob on a
circle present 40 s out of every 60 s), so memory is the detector's alone. RSS and the
state sizes are printed at the start and the end; the full 30-minute soak on the
simulator is ``benchmarks/soak.py``.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Iterator

import numpy as np
import pytest

from clusterfilter_ros.core.frame import AVIA, MID360, Frame
from clusterfilter_ros.core.params import detector_params
from clusterfilter_ros.core.streaming import StreamingDetector
from clusterfilter_ros.ros.merge import StampMerger

psutil = pytest.importorskip("psutil")

#: Stream length (s) of the CI soak, and the drone's on/off cycle.
STREAM_SECONDS = 180.0
CYCLE, PRESENT = 60.0, 40.0
T0 = 1_000.0
SAMPLE_EVERY = 10.0  # stream seconds between state samples


def drone_at(t: np.ndarray) -> np.ndarray:
    """Drone centre: a 15 m circle 15-21 m up, one lap per 40 s (~2.4 m/s)."""
    w = 2 * np.pi / 40.0
    t = np.asarray(t, dtype=np.float64)
    return np.stack([15 * np.cos(w * t), 15 * np.sin(w * t), 18 + 3 * np.sin(0.3 * t)], -1)


def drone_present(t: np.ndarray) -> np.ndarray:
    return (np.asarray(t) % CYCLE) < PRESENT


def stream(seconds: float, seed: int = 0) -> Iterator[Frame]:
    """Mid360 frames at 10 Hz (1200 static points) and Avia frames 50 ms later (20 sky
    noise points); both see ~20 drone points while the drone is present."""
    rng = np.random.default_rng(seed)
    wall = np.column_stack(
        [np.full(6000, 25.0), rng.uniform(-20, 20, 6000), rng.uniform(0, 12, 6000)]
    )
    tree = rng.normal([-10.0, 8.0, 6.0], [1.0, 1.0, 2.5], (3000, 3))
    ground = np.column_stack(
        [rng.uniform(-40, 40, 8000), rng.uniform(-40, 40, 8000), rng.normal(0, 0.05, 8000)]
    )
    static = np.concatenate([wall, tree, ground]).astype(np.float32)
    for k in range(int(seconds * 10)):
        for sensor, dt in ((MID360, 0.0), (AVIA, 0.05)):
            t = 0.1 * k + dt
            if sensor == MID360:
                pick = rng.integers(0, len(static), 1200)
                parts = [static[pick] + rng.normal(0, 0.02, (1200, 3)).astype(np.float32)]
            else:
                d = rng.normal(size=(20, 3))
                d[:, 2] = np.abs(d[:, 2]) + 1.0
                d /= np.linalg.norm(d, axis=1, keepdims=True)
                parts = [(d * rng.uniform(20, 300, (20, 1))).astype(np.float32)]
            if drone_present(t):
                parts.append((drone_at(t) + rng.normal(0, 0.12, (20, 3))).astype(np.float32))
            yield Frame(T0 + t, sensor, np.concatenate(parts))


def test_short_soak_bounded_state_and_detection_at_the_end(capsys) -> None:
    params = detector_params()
    detector = StreamingDetector(params)
    merger = StampMerger((AVIA, MID360), sync_timeout=0.25)
    process = psutil.Process()
    gc.collect()
    samples: list[dict[str, float]] = []
    estimates = []
    max_queue = 0
    next_sample = T0
    started = time.perf_counter()
    for frame in stream(STREAM_SECONDS):
        merger.add(frame, now=frame.stamp)
        max_queue = max(max_queue, len(merger))
        for item in merger.pop_ready(now=frame.stamp):
            estimate = detector.push(item.frame)
            if estimate is not None:
                estimates.append(estimate)
        if frame.stamp >= next_sample:
            stats = detector.stats()
            stats["rss_mb"] = process.memory_info().rss / 1e6
            stats["t"] = frame.stamp - T0
            samples.append(stats)
            next_sample += SAMPLE_EVERY
    wall = time.perf_counter() - started

    # --- bounded state: caps hold and nothing grows after the first minute
    steady = [s for s in samples if s["t"] >= 60.0]
    early = [s for s in samples if 20.0 <= s["t"] < 60.0 + 1e-6]
    for key in ("accumulator_voxels", "local_points", "state_bytes", "track_samples"):
        peak_late = max(s[key] for s in steady)
        peak_early = max(s[key] for s in early)
        assert peak_late <= 1.25 * peak_early + 100, (key, peak_early, peak_late)
    assert max(s["accumulator_voxels"] for s in samples) <= params.max_accumulator_voxels
    assert max(s["local_points"] for s in samples) <= params.max_local_points
    assert max_queue <= 4
    assert merger.counts.late == 0 and merger.counts.resets == 0
    rss_growth = steady[-1]["rss_mb"] - steady[0]["rss_mb"]
    assert rss_growth < 40.0, rss_growth

    # --- detection: as good in the last drone window as in the first, quiet without it
    stamps = np.array([e.stamp for e in estimates]) - T0
    xyz = np.array([e.position for e in estimates]).reshape(-1, 3)
    errors = np.linalg.norm(xyz - drone_at(stamps), axis=1)
    per_window = []
    for start in np.arange(0.0, STREAM_SECONDS, CYCLE):
        window = (stamps >= start + 2.0) & (stamps < start + PRESENT)
        frames_in_window = (PRESENT - 2.0) * 20
        per_window.append((window.sum() / frames_in_window, float(np.median(errors[window]))))
    absent = ~drone_present(stamps) & ((stamps % CYCLE) > PRESENT + 1.0)
    absent_frames = (CYCLE - PRESENT - 1.0) * 20 * len(per_window)
    first, last = per_window[0], per_window[-1]
    with capsys.disabled():
        print(
            f"\n[soak] {STREAM_SECONDS:.0f} s of stream ({len(samples)} samples) in {wall:.1f} s "
            f"wall ({STREAM_SECONDS / wall:.1f}x real time); RSS {samples[0]['rss_mb']:.0f} MB "
            f"at start, {steady[0]['rss_mb']:.0f} MB at 60 s, {samples[-1]['rss_mb']:.0f} MB at "
            f"end; accumulator {samples[0]['accumulator_voxels']:.0f} -> "
            f"{samples[-1]['accumulator_voxels']:.0f} voxels (peak "
            f"{max(s['accumulator_voxels'] for s in samples):.0f}), local history "
            f"{samples[-1]['local_points']:.0f} points, state "
            f"{samples[-1]['state_bytes'] / 1e6:.1f} MB, merge queue <= {max_queue}; "
            f"detection rate / median error first window {first[0]:.2f} / {first[1]:.3f} m, "
            f"last window {last[0]:.2f} / {last[1]:.3f} m; "
            f"{int(absent.sum())} estimates in {absent_frames:.0f} drone-free frames"
        )
    for rate, median in per_window:
        assert rate >= 0.7 and median < 0.3, per_window
    assert last[0] >= first[0] - 0.1, per_window
    assert absent.sum() <= 0.02 * absent_frames
