"""The detector's answer for one instant."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Estimate:
    """Drone position at one time.

    Attributes:
        stamp: time (s) the position is for (the stamp of the frame that produced it).
        position: (3,) float64 metres, ``target_offset`` already applied.
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
