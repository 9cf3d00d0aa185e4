"""Stamp glitches in the two-lidar merge (ROS-free): one bad stamp must not mute a lidar."""

from __future__ import annotations

import numpy as np

from clusterfilter_ros.core.frame import AVIA, MID360, Frame
from clusterfilter_ros.ros.merge import AddResult, StampMerger

EMPTY = np.zeros((0, 3), np.float32)


def _feed(merger: StampMerger, items, now: float = 0.0):
    """Add ``(stamp, sensor)`` items 10 ms apart; return (results, released (stamp, sensor))."""
    results, released = [], []
    for stamp, sensor in items:
        now += 0.01
        results.append(merger.add(Frame(stamp, sensor, EMPTY), now))
        released += [(m.frame.stamp, m.frame.sensor) for m in merger.pop_ready(now)]
    released += [(m.frame.stamp, m.frame.sensor) for m in merger.pop_ready(now + 10.0)]
    return results, released


def _both(start: float, n: int):
    return [(start + 0.1 * i, s) for i in range(n) for s in (AVIA, MID360)]


def test_one_zero_stamp_does_not_mute_the_other_lidar():
    merger = StampMerger((AVIA, MID360), sync_timeout=0.25)
    _feed(merger, _both(100.0, 10))
    results, released = _feed(merger, [(0.0, AVIA)] + _both(101.0, 10))
    assert results[0] is AddResult.RESET and merger.counts.resets == 1
    mid = [t for t, s in released if s == MID360]
    # At most the Mid360 frame that arrived before the Avia was back on time is lost.
    assert len(mid) >= 9 and mid[-1] == 101.9
    assert merger.counts.per_sensor_late.get(MID360, 0) <= 1


def test_one_far_future_stamp_recovers():
    merger = StampMerger((AVIA, MID360), sync_timeout=0.25)
    _feed(merger, _both(100.0, 10))
    results, released = _feed(merger, [(2e9, AVIA)] + _both(101.0, 10))
    assert merger.counts.resets == 1
    assert sum(s == MID360 and t >= 101.1 for t, s in released) >= 8
    assert sum(s == AVIA and t >= 101.1 for t, s in released) >= 8


def test_real_restart_still_drops_the_other_lidars_frames_in_flight():
    """The Avia's driver restarts (stamps jump back 50 s) while Mid360 frames from before
    the jump are still arriving: those are dropped until the Mid360 jumps back too."""
    merger = StampMerger((AVIA, MID360), sync_timeout=0.25)
    _feed(merger, _both(150.0, 10))
    in_flight = [(151.0 + 0.1 * i, MID360) for i in range(3)]
    after = _both(101.0, 5)
    results, released = _feed(merger, [(100.0, AVIA)] + in_flight + after)
    assert results[0] is AddResult.RESET
    assert all(r is AddResult.LATE for r in results[1:4])
    assert all(t < 110 for t, _ in released)
    assert sum(s == MID360 for _, s in released) == 5
