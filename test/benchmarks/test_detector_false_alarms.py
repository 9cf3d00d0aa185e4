"""False reports are put down to the class of the labelled returns near them."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from clusterfilter_ros.core.frame import TimedPositions
from clusterfilter_ros.sim.raycast import CLASS_BIRD, CLASS_DRONE, CLASS_STRUCTURE


def _recording(with_drone: bool):
    """Ten frames at 10 Hz: a bird at (10, 0, 20), a wall return at (40, 5, 8) and, with a
    drone, the drone at (0, 0, 30); the prism 0.2 m above the drone."""
    frames, classes = [], {}
    for i in range(10):
        xyz = [[10.0, 0.0, 20.0], [40.0, 5.0, 8.0]]
        cls = [CLASS_BIRD, CLASS_STRUCTURE]
        if with_drone:
            xyz.append([0.0, 0.0, 30.0])
            cls.append(CLASS_DRONE)
        frames.append(SimpleNamespace(stamp=0.1 * i, xyz=np.array(xyz, dtype=np.float32)))
        classes[i] = np.array(cls, dtype=np.int8)
    t = np.linspace(0.0, 1.0, 101)
    truth = TimedPositions(t, np.tile([0.0, 0.0, 30.0], (t.size, 1)))
    empty = TimedPositions(np.empty(0), np.empty((0, 3)))
    return SimpleNamespace(
        sequence=SimpleNamespace(frames=frames),
        classes=classes,
        prism_offset=np.array([0.0, 0.0, 0.2]),
        drone_truth=truth if with_drone else empty,
    )


def _reports(*positions):
    xyz = np.array(positions, dtype=np.float64) + [0.0, 0.0, 0.2]  # prism offset added
    return TimedPositions(np.linspace(0.2, 0.6, len(positions)), xyz)


def test_drone_free_reports_take_the_class_of_the_returns_near_them(benchmark_module):
    fa = benchmark_module("detector_false_alarms")
    counts = fa.attribute(_recording(False), _reports([10.5, 0, 20], [41, 5, 8], [0, 80, 30]))
    assert counts == {"bird": 1, "structure": 1, "none": 1}


def test_with_a_drone_only_reports_away_from_it_count(benchmark_module):
    fa = benchmark_module("detector_false_alarms")
    counts = fa.attribute(_recording(True), _reports([0.5, 0, 30], [10, 1, 20], [0, 2.5, 30]))
    # The first is the drone (0.5 m off); the third, 2.5 m off, counts, near its returns.
    assert counts == {"bird": 1, "drone": 1}
