"""The detector's answer for one instant."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clusterfilter_ros.core.params import ParamSet


@dataclass(frozen=True)
class Estimate:
    """Drone position at one time.

    Attributes:
        stamp: time (s) the position is for (the stamp of the frame that produced it).
        position: (3,) float64 metres, :func:`reported_positions` already applied.
        confidence: belief in [0, 1] that this is a drone.
        n_points: drone points supporting the position (within ``track_window`` s).
    """

    stamp: float
    position: np.ndarray
    confidence: float
    n_points: int

    def __post_init__(self) -> None:
        pos = np.asarray(self.position, dtype=np.float64).reshape(3)
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "stamp", float(self.stamp))
        object.__setattr__(self, "confidence", float(min(max(self.confidence, 0.0), 1.0)))
        object.__setattr__(self, "n_points", int(self.n_points))


def reported_positions(centres: np.ndarray, params: ParamSet) -> np.ndarray:
    """(N, 3) positions reported for (N, 3) centroids of drone returns: moved
    ``surface_depth`` away from ``viewpoint`` along the line of sight (the returns lie on
    the sensor-facing side of the drone), then shifted by ``target_offset``."""
    pos = np.array(centres, dtype=np.float64).reshape(-1, 3)
    depth = float(params.surface_depth)
    if depth > 0 and pos.size:
        ray = pos - np.asarray(params.viewpoint, dtype=np.float64)
        dist = np.linalg.norm(ray, axis=1, keepdims=True)
        pos += depth * ray / np.where(dist > 0, dist, 1.0)
    return pos + np.asarray(params.target_offset, dtype=np.float64)
