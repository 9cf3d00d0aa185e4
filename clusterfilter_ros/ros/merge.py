"""Merge the frames of several lidars into one stream in header-stamp order. ROS-free.

The detector must see frames in the same order whatever the timing of their arrival
(two topics, two DDS readers, an executor): then a node fed by a replay gives the same
answers as the offline streaming run on the same frames. :class:`StampMerger` holds a
small buffer per lidar and releases the frame with the smallest ``(stamp, sensor)`` key
as soon as no other lidar can still deliver a smaller one, i.e. once every other lidar
has either a frame queued or has already sent a stamp at least as late, or can no longer
send an earlier one because its next stamp is due no sooner than ``min_frame_interval``
after its last (a Livox at 10 Hz sends one frame every 0.1 s). That prediction keeps the
wait to the offset between the lidars' stamps (a few ms) instead of a whole frame
period. If a lidar is silent, a frame is released anyway after ``sync_timeout`` seconds
of wall clock.

Each lidar's own messages are assumed to arrive in stamp order (one DDS writer per
topic). A stamp earlier than the same lidar's previous one by more than
``backwards_tolerance`` (a looped bag, a restarted driver) starts a new *generation*:
the buffers are cleared and the consumer is expected to reset its state. The other
lidars' frames still in flight from before the jump (stamps not yet jumped back) are
dropped until their stamps jump back too, or until the jumped lidar's new stamps have
caught up with them (a single glitched stamp). Smaller steps back, duplicates, and frames
arriving after a later frame was already released are dropped and counted.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field
from enum import Enum

from clusterfilter_ros.core.frame import Frame


class AddResult(Enum):
    """What :meth:`StampMerger.add` did with a frame."""

    QUEUED = "queued"
    RESET = "reset"  # stamp jumped back: buffers cleared, new generation, frame queued
    LATE = "late"  # dropped: not later than what was already seen/released
    OVERFLOW = "overflow"  # queued, but the oldest queued frame was dropped to make room


@dataclass(frozen=True)
class MergedFrame:
    """A frame released by the merger, with its wall-clock receipt time and generation."""

    frame: Frame
    received_at: float
    generation: int


@dataclass
class MergerCounts:
    """Frames the merger dropped, by reason, since it was created."""

    late: int = 0
    overflow: int = 0
    resets: int = 0
    released_by_timeout: int = 0
    per_sensor_late: dict[str, int] = field(default_factory=dict)


class StampMerger:
    """Stamp-ordered merge of the frames of ``sensors`` (not thread-safe; lock outside).

    Args:
        sensors: names of the lidars expected (a frame of any other name is merged too,
            but nobody waits for that name).
        sync_timeout: longest wall-clock wait (s) for another lidar; 0 releases every
            frame at once (arrival order).
        max_queue: most frames held over all lidars; the oldest is dropped beyond it.
        backwards_tolerance: a stamp going back by more than this (s) starts a new
            generation; smaller steps back are dropped as late.
        min_frame_interval: shortest interval (s) between two stamps of one lidar; a
            frame is released without waiting for a lidar whose last stamp plus this
            interval is already later. 0 disables the prediction (always wait).
    """

    def __init__(
        self,
        sensors: tuple[str, ...] | list[str],
        sync_timeout: float = 0.25,
        max_queue: int = 50,
        backwards_tolerance: float = 0.5,
        min_frame_interval: float = 0.0,
    ) -> None:
        self.sensors = tuple(sensors)
        self.sync_timeout = float(sync_timeout)
        self.max_queue = int(max_queue)
        self.backwards_tolerance = float(backwards_tolerance)
        self.min_frame_interval = float(min_frame_interval)
        self.generation = 0
        self.counts = MergerCounts()
        self._queues: dict[str, collections.deque[tuple[Frame, float]]] = {
            s: collections.deque() for s in self.sensors
        }
        self._last_received: dict[str, float] = {}
        self._last_released: tuple[float, str] | None = None
        # lidar -> its last stamp before another lidar's jump back (see add()).
        self._awaiting_jump: dict[str, float] = {}

    def __len__(self) -> int:
        return sum(len(q) for q in self._queues.values())

    def clear(self) -> None:
        """Forget every queued frame and every stamp seen."""
        for q in self._queues.values():
            q.clear()
        self._last_received.clear()
        self._awaiting_jump.clear()
        self._last_released = None

    def _drop_late(self, sensor: str) -> AddResult:
        self.counts.late += 1
        self.counts.per_sensor_late[sensor] = self.counts.per_sensor_late.get(sensor, 0) + 1
        return AddResult.LATE

    def add(self, frame: Frame, now: float) -> AddResult:
        """Queue ``frame`` received at wall-clock time ``now`` (seconds, monotonic)."""
        sensor, stamp = frame.sensor, frame.stamp
        tol = self.backwards_tolerance
        result = AddResult.QUEUED
        if sensor in self._awaiting_jump:
            # Another lidar jumped back; this one's frames still in flight from before
            # the jump are stale until its own stamps jump back too, or until they fit
            # the new timeline (the jump was one glitched stamp, and the other lidar is
            # back at this one's time): else one bad stamp would mute this lidar for good.
            newest = max(self._last_received.values(), default=-math.inf)
            if stamp >= self._awaiting_jump[sensor] - tol and stamp > newest + tol:
                return self._drop_late(sensor)
            del self._awaiting_jump[sensor]
        last = self._last_received.get(sensor)
        released = self._last_released
        jumped_back = (last is not None and stamp < last - tol) or (
            released is not None and stamp < released[0] - tol
        )
        if jumped_back:
            previous = dict(self._last_received)
            self.clear()
            self._awaiting_jump = {s: t for s, t in previous.items() if s != sensor}
            self.generation += 1
            self.counts.resets += 1
            result = AddResult.RESET
        elif (last is not None and stamp <= last) or (
            released is not None and (stamp, sensor) <= released
        ):
            return self._drop_late(sensor)
        self._queues.setdefault(sensor, collections.deque()).append((frame, now))
        self._last_received[sensor] = stamp
        if len(self) > self.max_queue:
            oldest = min((q[0][0].stamp, s) for s, q in self._queues.items() if q)
            self._queues[oldest[1]].popleft()
            self.counts.overflow += 1
            # Nothing earlier than the dropped frame may be released after it.
            self._last_released = max(self._last_released or oldest, oldest)
            if result is AddResult.QUEUED:
                result = AddResult.OVERFLOW
        return result

    def _head(self) -> tuple[str, Frame, float] | None:
        heads = [(q[0][0].stamp, s) for s, q in self._queues.items() if q]
        if not heads:
            return None
        _, sensor = min(heads)
        frame, received_at = self._queues[sensor][0]
        return sensor, frame, received_at

    def _must_wait_for(self, sensor: str, stamp: float) -> bool:
        """Could another expected lidar still deliver a frame that sorts before this one?"""
        for other in self.sensors:
            if other == sensor or self._queues[other]:
                continue
            last = self._last_received.get(other)
            if last is None:
                return True
            if self.min_frame_interval > 0.0:
                if last + self.min_frame_interval <= stamp:
                    return True
            elif last < stamp:
                return True
        return False

    def pop_ready(self, now: float) -> list[MergedFrame]:
        """Release, in ``(stamp, sensor)`` order, every frame that can go now."""
        out: list[MergedFrame] = []
        while True:
            head = self._head()
            if head is None:
                break
            sensor, frame, received_at = head
            if self._must_wait_for(sensor, frame.stamp):
                if now - received_at < self.sync_timeout:
                    break
                self.counts.released_by_timeout += 1
            self._queues[sensor].popleft()
            self._last_released = (frame.stamp, sensor)
            out.append(MergedFrame(frame, received_at, self.generation))
        return out

    def next_deadline(self) -> float | None:
        """Wall-clock time at which the current head will be released by timeout, if any."""
        head = self._head()
        if head is None:
            return None
        return head[2] + self.sync_timeout
