"""Rigid transforms of lidar frames into the output frame (the extrinsic parameters). ROS-free."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence as SequenceABC

import numpy as np

from clusterfilter_ros.core.frame import Frame
from clusterfilter_ros.errors import ParameterError


@dataclasses.dataclass(frozen=True)
class Extrinsic:
    """A rotation ``rotation`` (3, 3) and translation ``translation`` (3,) in float64.

    A point ``p`` in the lidar's frame maps to ``rotation @ p + translation`` in the
    output frame.
    """

    rotation: np.ndarray
    translation: np.ndarray

    @property
    def is_identity(self) -> bool:
        return bool(np.array_equal(self.rotation, np.eye(3)) and not np.any(self.translation))

    @classmethod
    def from_list(cls, values: SequenceABC[float], name: str = "extrinsic") -> Extrinsic:
        """Build from ``[x, y, z, qx, qy, qz, qw]``; the quaternion is normalised.

        Raises :class:`ParameterError` naming ``name`` if the list has the wrong length,
        holds a non-finite number, or the quaternion is (near) zero.
        """
        arr = np.asarray(list(values), dtype=np.float64)
        if arr.shape != (7,):
            raise ParameterError(
                f"parameter '{name}' needs 7 values [x, y, z, qx, qy, qz, qw], got {arr.size}"
            )
        if not np.all(np.isfinite(arr)):
            raise ParameterError(f"parameter '{name}' must be finite, got {arr.tolist()}")
        q = arr[3:]
        norm = float(np.linalg.norm(q))
        if norm < 1e-9:
            raise ParameterError(
                f"parameter '{name}' has a zero quaternion; use [0, 0, 0, 1] for no rotation"
            )
        x, y, z, w = q / norm
        rotation = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        if x == 0.0 and y == 0.0 and z == 0.0:
            rotation = np.eye(3)
        return cls(rotation, arr[:3].copy())

    def apply(self, frame: Frame) -> Frame:
        """The frame with its points mapped into the output frame (same object if identity)."""
        if self.is_identity or len(frame) == 0:
            return frame
        xyz = frame.xyz.astype(np.float64) @ self.rotation.T + self.translation
        return dataclasses.replace(frame, xyz=xyz.astype(np.float32))
