"""In-memory data types shared by every layer."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Canonical sensor names used throughout the package.
AVIA = "avia"
MID360 = "mid360"
SENSORS = (AVIA, MID360)


@dataclass(frozen=True)
class Frame:
    """One lidar scan.

    Attributes:
        stamp: scan time in seconds (float, e.g. ROS header stamp or challenge file name).
        sensor: sensor name, normally :data:`AVIA` or :data:`MID360`.
        xyz: (N, 3) float32 point coordinates in metres. Padding rows are already removed.
        intensity: optional (N,) float32 reflectivity/intensity.
        point_time: optional (N,) float64 per-point time offset in seconds relative to
            ``stamp`` (Livox ``offset_time`` or the driver's ``timestamp`` field minus stamp).
    """

    stamp: float
    sensor: str
    xyz: np.ndarray
    intensity: np.ndarray | None = None
    point_time: np.ndarray | None = None

    def __post_init__(self) -> None:
        xyz = np.asarray(self.xyz)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise ValueError(f"Frame.xyz must have shape (N, 3), got {xyz.shape}")
        if xyz.dtype != np.float32:
            xyz = xyz.astype(np.float32)
        object.__setattr__(self, "xyz", xyz)
        n = xyz.shape[0]
        for name, dtype in (("intensity", np.float32), ("point_time", np.float64)):
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.asarray(value, dtype=dtype).reshape(-1)
            if arr.shape[0] != n:
                raise ValueError(f"Frame.{name} has {arr.shape[0]} values for {n} points")
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "stamp", float(self.stamp))

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


@dataclass(frozen=True)
class TimedPositions:
    """Positions over time: ground truth, or estimates.

    Attributes:
        stamps: (M,) float64 seconds, strictly increasing after construction.
        xyz: (M, 3) float64 metres.
    """

    stamps: np.ndarray
    xyz: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        stamps = np.asarray(self.stamps, dtype=np.float64).reshape(-1)
        xyz = np.asarray(self.xyz, dtype=np.float64).reshape(-1, 3)
        if stamps.shape[0] != xyz.shape[0]:
            raise ValueError(f"{stamps.shape[0]} stamps for {xyz.shape[0]} positions")
        order = np.argsort(stamps, kind="stable")
        object.__setattr__(self, "stamps", stamps[order])
        object.__setattr__(self, "xyz", xyz[order])
        object.__setattr__(self, "extra", {k: np.asarray(v)[order] for k, v in self.extra.items()})

    def __len__(self) -> int:
        return int(self.stamps.shape[0])


@dataclass
class Sequence:
    """A recording: lidar frames of all sensors in time order, plus optional ground truth."""

    name: str
    frames: list[Frame]
    ground_truth: TimedPositions | None = None

    def sensors(self) -> list[str]:
        return sorted({f.sensor for f in self.frames})

    @property
    def start(self) -> float:
        return self.frames[0].stamp if self.frames else float("nan")

    @property
    def end(self) -> float:
        return self.frames[-1].stamp if self.frames else float("nan")
