"""Hand-made scenes with known answers for the detector tests."""

from __future__ import annotations

import numpy as np
import pytest

from clusterfilter_ros.core.frame import AVIA, MID360, Frame


def drone_path(t: np.ndarray) -> np.ndarray:
    """A drone flying a 15 m radius circle at 20 m height, ~4.7 m/s."""
    w = 2 * np.pi / 20.0
    return np.stack([15 * np.cos(w * t), 15 * np.sin(w * t), 20 + 2 * np.sin(0.5 * t)], axis=1)


def build_scene(
    duration: float = 10.0,
    seed: int = 0,
    drone: bool = True,
    drone_points: int = 3,
    wall_points: int = 800,
    noise_points: int = 40,
) -> tuple[list[Frame], np.ndarray, np.ndarray]:
    """Frames of a static wall (Mid360), sparse Avia sky noise and optionally a drone.

    Returns (frames in stamp order, drone truth stamps, drone truth xyz).
    """
    rng = np.random.default_rng(seed)
    frames: list[Frame] = []
    truth_t, truth_xyz = [], []
    for i in range(int(duration * 10)):
        for sensor, dt in ((MID360, 0.0), (AVIA, 0.004)):
            stamp = 1000.0 + i * 0.1 + dt
            parts = []
            if sensor == MID360:
                wall = np.column_stack(
                    [
                        np.full(wall_points, 40.0) + rng.normal(0, 0.02, wall_points),
                        rng.uniform(-20, 20, wall_points),
                        rng.uniform(0, 15, wall_points),
                    ]
                )
                parts.append(wall)
            else:
                d = rng.normal(size=(noise_points, 3))
                d[:, 2] = np.abs(d[:, 2]) + 1.0
                d /= np.linalg.norm(d, axis=1, keepdims=True)
                parts.append(d * rng.uniform(20, 400, (noise_points, 1)))
            if drone:
                p = drone_path(np.array([stamp - 1000.0]))[0]
                truth_t.append(stamp)
                truth_xyz.append(p)
                parts.append(p + rng.normal(0, 0.1, (drone_points, 3)))
            xyz = np.vstack(parts).astype(np.float32)
            frames.append(Frame(stamp, sensor, xyz))
    return frames, np.asarray(truth_t), np.asarray(truth_xyz).reshape(-1, 3)


@pytest.fixture
def scene():
    return build_scene


@pytest.fixture
def drone_path_fn():
    return drone_path
