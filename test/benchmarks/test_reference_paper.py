"""The benchmark's reference implementation of the paper picks a moving blob over a wall."""

from __future__ import annotations

import numpy as np

from clusterfilter_ros.core.frame import AVIA, MID360, Frame


def _scene(n_frames: int = 60, seed: int = 0) -> tuple[list[Frame], np.ndarray]:
    """A static wall (dense, every frame) and a drone blob moving at 5 m/s."""
    rng = np.random.default_rng(seed)
    frames: list[Frame] = []
    truth = []
    for i in range(n_frames):
        t = 100.0 + 0.1 * i
        wall = np.column_stack(
            [rng.uniform(0, 4, 60), np.full(60, 10.0), rng.uniform(6, 9, 60)]
        ) + rng.normal(0, 0.02, (60, 3))
        ground = np.column_stack(
            [rng.uniform(-20, 20, 200), rng.uniform(-20, 20, 200), rng.normal(0, 0.05, 200)]
        )
        centre = np.array([-10.0 + 0.5 * i, -5.0, 20.0])
        truth.append(centre)
        blob = centre + rng.normal(0, 0.15, (6, 3))
        frames.append(Frame(t, MID360, np.vstack([wall, ground]).astype(np.float32)))
        noise = rng.uniform([-300, -300, 50], [300, 300, 400], (5, 3))
        frames.append(Frame(t + 0.003, AVIA, np.vstack([blob, noise]).astype(np.float32)))
    stamps = 100.0 + 0.1 * np.arange(n_frames)
    return frames, (stamps, np.array(truth))


def test_reference_selects_the_moving_blob(benchmark_module) -> None:
    reference_paper = benchmark_module("reference_paper")
    frames, (stamps, truth) = _scene()
    result = reference_paper.reference_detect(frames, stamps)
    assert result.n_candidates >= 1
    assert len(result.estimate) > 0.8 * len(stamps)
    idx = np.searchsorted(stamps, result.estimate.stamps)
    err = np.linalg.norm(result.estimate.xyz - truth[idx], axis=1)
    assert np.median(err) < 0.5
    assert {"avia_denoise", "global_dbscan", "local_scoring", "spline"} <= set(result.timings)


def test_reference_without_candidates_returns_no_estimate(benchmark_module) -> None:
    reference_paper = benchmark_module("reference_paper")
    frames, (stamps, _) = _scene()
    without_drone = [Frame(f.stamp, f.sensor, f.xyz[f.xyz[:, 2] < 15]) for f in frames]
    result = reference_paper.reference_detect(without_drone, stamps)
    assert result.n_candidates == 0 or result.estimate.xyz[:, 2].max() < 15
    assert reference_paper.reference_detect([], stamps).n_candidates == 0
