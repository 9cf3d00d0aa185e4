"""The kinematic measures of selected clusters on constructed paths."""

from __future__ import annotations

import numpy as np


def _track(kind: str, seconds: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """Two returns a frame at 10 Hz, 5 cm noise: ``straight`` at 6 m/s; ``turn``, a level
    turn at 6 m/s on a 12 m radius (3 m/s^2 turning at 0.5 rad/s); ``weave``, straight at
    6 m/s swinging 1.5 m sideways and up and down over a 5 s period (2.4 m/s^2)."""
    t = np.repeat(np.arange(0.0, seconds, 0.1), 2)
    if kind == "turn":
        angle = t * 0.5
        xyz = np.stack([12.0 * np.cos(angle), 12.0 * np.sin(angle), np.full_like(t, 20.0)], 1)
    else:
        swing = 1.5 * np.sin(2 * np.pi * t / 5.0) if kind == "weave" else np.zeros_like(t)
        xyz = np.stack([6.0 * t, swing, 20.0 + swing], axis=1)
    return t, xyz + np.random.default_rng(0).normal(0.0, 0.05, xyz.shape)


def test_the_acceleration_change_grows_from_a_line_to_a_turn_to_a_weave(benchmark_module):
    sk = benchmark_module("selection_kinematics")
    centres, acc = sk.window_accelerations(*_track("turn"), window=3.0)
    # Windows slid by 0.25 s over 10 s, each fitting the turn's 3 m/s^2, level.
    assert centres.size > 25
    assert np.allclose(np.linalg.norm(acc, axis=1), 3.0, atol=0.3)
    straight = sk.kinematics(*_track("straight"), window=3.0)
    turn = sk.kinematics(*_track("turn"), window=3.0)
    weave = sk.kinematics(*_track("weave"), window=3.0)
    # The turn's acceleration turns by 0.75 rad in 1.5 s: 2 x 3 x sin(0.375) / 1.5.
    assert straight["accel_change"] < 0.2
    assert abs(turn["accel_change"] - 6.0 * np.sin(0.375) / 1.5) < 0.15
    assert weave["accel_change"] > 1.8
    assert straight["vertical_accel"] < 0.1 and turn["vertical_accel"] < 0.1
    assert weave["vertical_accel"] > 0.8


def test_too_short_a_track_has_no_measure(benchmark_module):
    sk = benchmark_module("selection_kinematics")
    m = sk.kinematics(*_track("straight", seconds=1.0), window=3.0)
    assert np.isnan(m["accel_change"]) and np.isnan(m["vertical_accel"])
    centres, acc = sk.window_accelerations(np.empty(0), np.empty((0, 3)), 3.0)
    assert centres.size == 0 and acc.shape == (0, 3)


def test_the_summary_gives_percentiles_per_class(benchmark_module):
    sk = benchmark_module("selection_kinematics")
    rows = [
        {"class": "drone", "fitted_accel": 2.0, "accel_change": 0.5, "vertical_accel": 0.2},
        {"class": "drone", "fitted_accel": 3.0, "accel_change": 1.5, "vertical_accel": 0.4},
        {"class": "bird", "fitted_accel": 5.0, "accel_change": float("nan"), "vertical_accel": 1},
    ]
    text = sk.summary(rows)
    assert "| drone | 2 | accel_change | 0.60 | 1.00 |" in text
    assert "| bird | 1 | fitted_accel |" in text and "| bird | 0 |" not in text
    assert "bird | 1 | accel_change" not in text  # no finite value
