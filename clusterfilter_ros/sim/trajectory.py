"""Smooth, speed- and acceleration-limited paths through waypoints.

A path is a chain of quintic Hermite segments between knots. Each knot has a position,
a velocity (zero at stops and hovers, otherwise the Catmull-Rom estimate from its
neighbours, capped at the cruise speed) and zero acceleration, so position, velocity
and acceleration are continuous and jerk is bounded. Segment durations start from
distance / cruise speed and are stretched until the sampled speed and acceleration stay
within the limits. Hovering is a knot repeated with a hold time. Before the first knot
the object waits at the first position; after the last it stays at the last.

Used for drones, walking people, the car and (with high limits plus jitter) birds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Waypoint:
    """A point to fly through; ``hold`` > 0 stops there for that many seconds.

    ``speed`` is the cruise speed (m/s) on the leg arriving at this waypoint (None: the
    path's default).
    """

    position: tuple[float, float, float]
    hold: float = 0.0
    speed: float | None = None


def _quintic_coeffs(p0, v0, p1, v1, duration):
    """Polynomial coefficients c0..c5 (each (K, 3)) of quintic Hermite segments, a = 0 at ends."""
    T = duration[:, None]
    c0 = p0
    c1 = v0 * T
    c3 = 10 * (p1 - p0) - (6 * v0 + 4 * v1) * T
    c4 = -15 * (p1 - p0) + (8 * v0 + 7 * v1) * T
    c5 = 6 * (p1 - p0) - (3 * v0 + 3 * v1) * T
    return c0, c1, np.zeros_like(p0), c3, c4, c5


class Path:
    """A smooth path through waypoints starting at ``start_time`` (seconds).

    Evaluate with :meth:`position`, :meth:`velocity`, :meth:`acceleration` on arrays of
    times (any shape; the result has a trailing axis of 3).
    """

    def __init__(
        self,
        waypoints: list[Waypoint],
        start_time: float = 0.0,
        cruise_speed: float = 5.0,
        max_speed: float = 12.0,
        max_acceleration: float = 4.0,
    ) -> None:
        if not waypoints:
            raise ValueError("a path needs at least one waypoint")
        positions: list[np.ndarray] = []
        stop: list[bool] = []
        leg_speed: list[float] = []
        holds: list[float] = []
        for i, wp in enumerate(waypoints):
            p = np.asarray(wp.position, dtype=np.float64)
            speed = min(wp.speed if wp.speed is not None else cruise_speed, max_speed)
            first_or_last = i == 0 or i == len(waypoints) - 1
            positions.append(p)
            stop.append(wp.hold > 0 or first_or_last)
            leg_speed.append(speed)
            holds.append(0.0)
            if wp.hold > 0:
                positions.append(p)
                stop.append(True)
                leg_speed.append(speed)
                holds.append(wp.hold)
        self.knots = np.array(positions)
        self.stop = np.array(stop)
        self.max_speed = max_speed
        self.max_acceleration = max_acceleration
        n_seg = len(self.knots) - 1
        dist = np.linalg.norm(np.diff(self.knots, axis=0), axis=1)
        hold_arr = np.array(holds[1:]) if n_seg else np.zeros(0)
        is_hold = hold_arr > 0
        cruise = np.array(leg_speed[1:]) if n_seg else np.zeros(0)
        durations = np.where(is_hold, hold_arr, np.maximum(dist / np.maximum(cruise, 0.1), 0.3))
        for _ in range(40):
            velocities = self._knot_velocities(durations, cruise)
            peak_v, peak_a = self._segment_peaks(durations, velocities)
            stretch = np.maximum(peak_v / (max_speed * 0.999), 1.0)
            stretch = np.maximum(stretch, np.sqrt(peak_a / (max_acceleration * 0.999)))
            stretch[is_hold] = 1.0
            if np.all(stretch <= 1.0 + 1e-3):
                break
            grow = stretch > 1.0 + 1e-3
            durations = np.where(grow, durations * np.minimum(stretch**0.7 * 1.01, 3.0), durations)
        for _ in range(10):  # safety net: stretch every moving leg uniformly
            velocities = self._knot_velocities(durations, cruise)
            peak_v, peak_a = self._segment_peaks(durations, velocities)
            factor = max(
                float(np.max(peak_v[~is_hold] / max_speed, initial=0.0)),
                float(np.sqrt(np.max(peak_a[~is_hold] / max_acceleration, initial=0.0))),
            )
            if factor <= 1.0:
                break
            durations = np.where(is_hold, durations, durations * factor * 1.01)
        self.durations = durations
        self.velocities = self._knot_velocities(durations, cruise)
        self.knot_times = start_time + np.concatenate([[0.0], np.cumsum(durations)])
        if n_seg:
            self._coeffs = _quintic_coeffs(
                self.knots[:-1],
                self.velocities[:-1],
                self.knots[1:],
                self.velocities[1:],
                durations,
            )

    @property
    def start_time(self) -> float:
        return float(self.knot_times[0])

    @property
    def end_time(self) -> float:
        return float(self.knot_times[-1])

    def _knot_velocities(self, durations: np.ndarray, cruise: np.ndarray) -> np.ndarray:
        v = np.zeros_like(self.knots)
        if len(self.knots) < 3:
            return v
        span = durations[:-1] + durations[1:]
        est = (self.knots[2:] - self.knots[:-2]) / span[:, None]
        cap = np.minimum(cruise[:-1], cruise[1:])
        norm = np.linalg.norm(est, axis=1)
        est *= np.minimum(1.0, cap / np.maximum(norm, 1e-9))[:, None]
        v[1:-1] = est
        v[self.stop] = 0.0
        return v

    def _segment_peaks(
        self, durations: np.ndarray, velocities: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        s = np.linspace(0.0, 1.0, 33)
        c = _quintic_coeffs(
            self.knots[:-1], velocities[:-1], self.knots[1:], velocities[1:], durations
        )
        vel = (
            c[1][:, None]
            + 3 * c[3][:, None] * s[None, :, None] ** 2
            + 4 * c[4][:, None] * s[None, :, None] ** 3
            + 5 * c[5][:, None] * s[None, :, None] ** 4
        ) / durations[:, None, None]
        acc = (
            6 * c[3][:, None] * s[None, :, None]
            + 12 * c[4][:, None] * s[None, :, None] ** 2
            + 20 * c[5][:, None] * s[None, :, None] ** 3
        ) / durations[:, None, None] ** 2
        return np.linalg.norm(vel, axis=2).max(axis=1), np.linalg.norm(acc, axis=2).max(axis=1)

    def _evaluate(self, t: np.ndarray, derivative: int) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        flat = t.reshape(-1)
        out = np.zeros((flat.shape[0], 3))
        if len(self.knots) == 1:
            if derivative == 0:
                out[:] = self.knots[0]
            return out.reshape(t.shape + (3,))
        seg = np.clip(
            np.searchsorted(self.knot_times, flat, side="right") - 1, 0, len(self.durations) - 1
        )
        dur = self.durations[seg]
        s = np.clip((flat - self.knot_times[seg]) / dur, 0.0, 1.0)[:, None]
        c0, c1, _, c3, c4, c5 = (c[seg] for c in self._coeffs)
        if derivative == 0:
            out = c0 + s * (c1 + s * s * (c3 + s * (c4 + s * c5)))
        elif derivative == 1:
            out = (c1 + s * s * (3 * c3 + s * (4 * c4 + 5 * s * c5))) / dur[:, None]
        else:
            out = (s * (6 * c3 + s * (12 * c4 + 20 * s * c5))) / dur[:, None] ** 2
        if derivative > 0:
            outside = (flat < self.knot_times[0]) | (flat > self.knot_times[-1])
            out[outside] = 0.0
        return out.reshape(t.shape + (3,))

    def position(self, t: np.ndarray | float) -> np.ndarray:
        return self._evaluate(np.asarray(t), 0)

    def velocity(self, t: np.ndarray | float) -> np.ndarray:
        return self._evaluate(np.asarray(t), 1)

    def acceleration(self, t: np.ndarray | float) -> np.ndarray:
        return self._evaluate(np.asarray(t), 2)


class Wobble:
    """Smooth small random motion (sum of sinusoids per axis): wind drift, erratic flight.

    ``amplitude`` (m) and ``period`` range (s) set its size and speed; deterministic in
    ``rng``.
    """

    def __init__(
        self,
        rng: np.random.Generator,
        amplitude: tuple[float, float, float],
        period: tuple[float, float],
        terms: int = 3,
    ) -> None:
        self.omega = 2 * np.pi / rng.uniform(period[0], period[1], size=(terms, 3))
        self.phase = rng.uniform(0, 2 * np.pi, size=(terms, 3))
        weights = rng.uniform(0.5, 1.0, size=(terms, 3))
        weights /= weights.sum(axis=0, keepdims=True)
        self.amp = weights * np.asarray(amplitude)[None, :]

    def position(self, t: np.ndarray | float) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)[..., None, None]
        return (self.amp * np.sin(self.omega * t + self.phase)).sum(axis=-2)

    def velocity(self, t: np.ndarray | float) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)[..., None, None]
        return (self.amp * self.omega * np.cos(self.omega * t + self.phase)).sum(axis=-2)

    def acceleration(self, t: np.ndarray | float) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)[..., None, None]
        return -(self.amp * self.omega**2 * np.sin(self.omega * t + self.phase)).sum(axis=-2)
