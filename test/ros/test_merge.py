"""StampMerger: stamp-ordered, deterministic merge of two lidar streams (ROS-free)."""

import random

import numpy as np

from clusterfilter_ros.core.frame import Frame
from clusterfilter_ros.ros.merge import AddResult, StampMerger

SENSORS = ("avia", "mid360")


def frame(sensor: str, stamp: float) -> Frame:
    return Frame(stamp=stamp, sensor=sensor, xyz=np.zeros((1, 3), np.float32))


def two_streams(n: int = 30) -> list[Frame]:
    frames = [frame("avia", 0.1 * i) for i in range(n)]
    frames += [frame("mid360", 0.1 * i + (0.05 if i % 3 else 0.0)) for i in range(n)]
    return sorted(frames, key=lambda f: (f.stamp, f.sensor))


def test_any_interleaving_of_in_order_streams_gives_stamp_order():
    expected = [(f.stamp, f.sensor) for f in two_streams()]
    rng = random.Random(4)
    for _ in range(20):
        per_sensor = {s: [f for f in two_streams() if f.sensor == s] for s in SENSORS}
        merger = StampMerger(SENSORS, sync_timeout=10.0, max_queue=1000)
        released = []
        while any(per_sensor.values()):
            s = rng.choice([s for s in SENSORS if per_sensor[s]])
            assert merger.add(per_sensor[s].pop(0), now=0.0) is AddResult.QUEUED
            released += merger.pop_ready(now=0.0)
        released += merger.pop_ready(now=100.0)  # the tail is released by timeout
        assert [(m.frame.stamp, m.frame.sensor) for m in released] == expected


def test_waits_for_the_other_lidar_then_times_out():
    merger = StampMerger(SENSORS, sync_timeout=0.2)
    merger.add(frame("avia", 1.0), now=10.0)
    assert merger.pop_ready(now=10.1) == []
    assert merger.next_deadline() == 10.2
    out = merger.pop_ready(now=10.25)
    assert [m.frame.stamp for m in out] == [1.0]
    assert merger.counts.released_by_timeout == 1
    # mid360 arriving later with an earlier stamp is dropped as late, not reordered
    assert merger.add(frame("mid360", 0.9), now=10.3) is AddResult.LATE
    assert merger.counts.late == 1


def test_zero_timeout_is_arrival_order():
    merger = StampMerger(SENSORS, sync_timeout=0.0)
    merger.add(frame("mid360", 2.0), now=0.0)
    assert [m.frame.sensor for m in merger.pop_ready(now=0.0)] == ["mid360"]


def test_backward_jump_starts_new_generation_and_clears():
    merger = StampMerger(SENSORS, sync_timeout=1.0, backwards_tolerance=0.5)
    for t in (5.0, 5.1):
        merger.add(frame("avia", t), now=0.0)
    merger.add(frame("mid360", 5.0), now=0.0)
    assert merger.add(frame("avia", 5.05), now=0.0) is AddResult.LATE  # small step back
    assert merger.add(frame("avia", 0.0), now=0.0) is AddResult.RESET  # looped bag
    assert merger.generation == 1 and len(merger) == 1
    out = merger.pop_ready(now=5.0)
    assert [(m.frame.stamp, m.generation) for m in out] == [(0.0, 1)]


def test_overflow_drops_oldest():
    merger = StampMerger(SENSORS, sync_timeout=10.0, max_queue=3)
    results = [merger.add(frame("avia", t), now=0.0) for t in (1.0, 2.0, 3.0, 4.0)]
    assert results[-1] is AddResult.OVERFLOW
    assert merger.counts.overflow == 1
    out = merger.pop_ready(now=100.0)
    assert [m.frame.stamp for m in out] == [2.0, 3.0, 4.0]


def test_loop_with_other_lidar_tail_in_flight_resets_once():
    merger = StampMerger(SENSORS, sync_timeout=10.0, backwards_tolerance=0.5)
    merger.add(frame("avia", 101.9), now=0.0)
    merger.add(frame("mid360", 101.85), now=0.0)
    merger.pop_ready(now=0.0)
    assert merger.add(frame("avia", 100.0), now=0.0) is AddResult.RESET
    # mid360's last frame of the first pass arrives after avia looped: stale, dropped
    assert merger.add(frame("mid360", 101.95), now=0.0) is AddResult.LATE
    assert merger.add(frame("mid360", 100.0), now=0.0) is AddResult.QUEUED
    assert merger.counts.resets == 1
    out = merger.pop_ready(now=0.0)
    assert [(m.frame.stamp, m.frame.sensor, m.generation) for m in out] == [
        (100.0, "avia", 1),
        (100.0, "mid360", 1),
    ]


def test_min_frame_interval_releases_without_waiting_a_whole_period():
    """With 10 Hz lidars offset by 3 ms, each frame goes as soon as the other lidar's
    next stamp can no longer sort before it; the order is still (stamp, sensor)."""
    merger = StampMerger(SENSORS, sync_timeout=10.0, min_frame_interval=0.05)
    released = []
    for i in range(5):
        t = 0.1 * i
        merger.add(frame("mid360", t), now=0.0)
        # mid360 at t waits: avia (last at t - 97 ms) may still send t + 3 ms
        assert merger.pop_ready(now=0.0) == []
        merger.add(frame("avia", t + 0.003), now=0.0)
        batch = merger.pop_ready(now=0.0)
        # both go at once: mid360's next stamp is >= t + 50 ms, after avia's t + 3 ms
        assert [m.frame.sensor for m in batch] == ["mid360", "avia"]
        released += batch
    order = [(m.frame.stamp, m.frame.sensor) for m in released]
    assert order == sorted(order)
    assert len(merger) == 0 and merger.counts.released_by_timeout == 0


def test_min_frame_interval_still_waits_when_the_other_may_be_earlier():
    merger = StampMerger(SENSORS, sync_timeout=10.0, min_frame_interval=0.05)
    merger.add(frame("avia", 1.0), now=0.0)
    merger.add(frame("mid360", 1.01), now=0.0)
    # avia's next stamp is >= 1.05, so mid360 at 1.01 need not wait for it
    assert [m.frame.stamp for m in merger.pop_ready(now=0.0)] == [1.0, 1.01]
    merger.add(frame("mid360", 1.2), now=0.0)
    # avia may still send 1.1 (1.0 + 0.05 <= 1.2): mid360 at 1.2 waits for it
    assert merger.pop_ready(now=0.0) == []
    merger.add(frame("avia", 1.1), now=0.0)
    # avia's next may still come at 1.15..1.2: 1.2 keeps waiting until it does
    assert [m.frame.stamp for m in merger.pop_ready(now=0.0)] == [1.1]
    merger.add(frame("avia", 1.203), now=0.0)
    assert [m.frame.stamp for m in merger.pop_ready(now=0.0)] == [1.2, 1.203]
