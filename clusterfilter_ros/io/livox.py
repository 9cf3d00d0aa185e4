"""Livox ``CustomMsg`` (livox_ros_driver and livox_ros_driver2) from raw serialized bytes.

Message definition (identical in both drivers)::

    std_msgs/Header header
    uint64 timebase          # ns, time of the first point
    uint32 point_num
    uint8 lidar_id
    uint8[3] rsvd
    CustomPoint[] points     # uint32 offset_time (ns from timebase), float32 x, y, z,
                             # uint8 reflectivity, uint8 tag, uint8 line

The points are read through one numpy view over the bytes (ROS 1: packed 19-byte
records; ROS 2 CDR: 19-byte records on a 20-byte stride, the last one unpadded), never
by decoding a Python object per point.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from clusterfilter_ros.core.frame import Frame
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.pointcloud2 import (
    MAX_ROS1_SEC,
    MAX_ROS2_SEC,
    finite_rows,
    seconds_to_stamp,
)

#: Message type names (ROS 2 form) of the two drivers.
CUSTOM_MSG_TYPES = ("livox_ros_driver/msg/CustomMsg", "livox_ros_driver2/msg/CustomMsg")
CUSTOM_POINT_DEFINITION = """uint32 offset_time
float32 x
float32 y
float32 z
uint8 reflectivity
uint8 tag
uint8 line
"""
CUSTOM_MSG_DEFINITION = """std_msgs/Header header
uint64 timebase
uint32 point_num
uint8 lidar_id
uint8[3] rsvd
CustomPoint[] points
"""

_POINT_FIELDS = {
    "names": ["offset_time", "x", "y", "z", "reflectivity", "tag", "line"],
    "formats": ["u4", "f4", "f4", "f4", "u1", "u1", "u1"],
    "offsets": [0, 4, 8, 12, 16, 17, 18],
}
_POINT_SIZE = 19
_CDR_POINT_STRIDE = 20


class MalformedCustomMsgError(InputError):
    """Bytes that are not a complete Livox CustomMsg."""


def is_custom_msg_type(msgtype: str) -> bool:
    """True for ``livox_ros_driver[2]/msg/CustomMsg`` (ROS 2) or ``.../CustomMsg`` (ROS 1)."""
    pkg, _, name = msgtype.replace("/msg/", "/").partition("/")
    return name == "CustomMsg" and pkg in ("livox_ros_driver", "livox_ros_driver2")


def point_dtype(big_endian: bool = False) -> np.dtype:
    """Structured dtype of one CustomPoint record (19 bytes, no padding)."""
    order = ">" if big_endian else "<"
    formats = [order + f if f != "u1" else f for f in _POINT_FIELDS["formats"]]
    return np.dtype({**_POINT_FIELDS, "formats": formats, "itemsize": _POINT_SIZE})


@dataclass(frozen=True)
class CustomMsgData:
    """A decoded CustomMsg: header, metadata and the points as one structured array."""

    sec: int
    nanosec: int
    frame_id: str
    timebase: int
    point_num: int
    lidar_id: int
    points: np.ndarray  # structured, fields of CustomPoint

    @property
    def stamp(self) -> float:
        return self.sec + self.nanosec * 1e-9


@dataclass(frozen=True)
class DecodedCustomMsg:
    """A CustomMsg as a :class:`Frame` plus what was dropped and the raw metadata."""

    frame: Frame
    n_points: int
    n_dropped_nonfinite: int
    timebase: int
    lidar_id: int
    frame_id: str
    tag: np.ndarray
    line: np.ndarray


class _Cursor:
    """Reads primitives from serialized bytes, with CDR alignment when ``align``."""

    def __init__(self, raw: memoryview, start: int, order: str, align: bool, what: str) -> None:
        self.raw, self.pos, self.origin = raw, start, start
        self.order, self.align, self.what = order, align, what

    def _need(self, n: int) -> None:
        if self.pos + n > len(self.raw):
            raise MalformedCustomMsgError(
                f"{self.what}: truncated ({len(self.raw)} bytes, need more than {self.pos + n - 1})"
            )

    def _align(self, size: int) -> None:
        if self.align:
            self.pos += -(self.pos - self.origin) % size

    def read(self, fmt: str) -> Any:
        size = struct.calcsize(fmt)
        self._align(size)
        self._need(size)
        value = struct.unpack_from(self.order + fmt, self.raw, self.pos)[0]
        self.pos += size
        return value

    def read_bytes(self, n: int) -> bytes:
        self._need(n)
        value = bytes(self.raw[self.pos : self.pos + n])
        self.pos += n
        return value

    def read_string(self, cdr: bool) -> str:
        length = self.read("I")
        if length > len(self.raw):
            raise MalformedCustomMsgError(f"{self.what}: string length {length} exceeds message")
        data = self.read_bytes(length)
        if cdr and data.endswith(b"\0"):
            data = data[:-1]
        return data.decode("utf-8", errors="replace")


def parse_custom_msg(
    raw: bytes | bytearray | memoryview | np.ndarray, ros_version: int = 2, what: str = "CustomMsg"
) -> CustomMsgData:
    """Parse serialized CustomMsg bytes.

    Args:
        raw: ROS 2: CDR bytes *with* the 4-byte encapsulation header (as stored in ROS 2
            bags and produced by ``rclpy.serialization``). ROS 1: the message bytes as
            stored in a ROS 1 bag.
        ros_version: 1 or 2.
        what: name used in error messages (e.g. bag and topic).
    """
    view = memoryview(
        np.ascontiguousarray(raw, dtype=np.uint8) if isinstance(raw, np.ndarray) else raw
    ).cast("B")
    if ros_version == 2:
        if len(view) < 4:
            raise MalformedCustomMsgError(f"{what}: {len(view)} bytes, too short for CDR")
        kind = view[1]
        if view[0] != 0 or kind not in (0, 1):
            raise MalformedCustomMsgError(
                f"{what}: unknown CDR encapsulation {bytes(view[:2]).hex()}"
            )
        order = "<" if kind == 1 else ">"
        cur = _Cursor(view, 4, order, True, what)
        sec, nanosec = cur.read("i"), cur.read("I")
        frame_id = cur.read_string(cdr=True)
    elif ros_version == 1:
        order = "<"
        cur = _Cursor(view, 0, order, False, what)
        cur.read("I")  # seq
        sec, nanosec = cur.read("I"), cur.read("I")
        frame_id = cur.read_string(cdr=False)
    else:
        raise ValueError(f"ros_version must be 1 or 2, got {ros_version}")
    timebase = cur.read("Q")
    point_num = cur.read("I")
    lidar_id = cur.read("B")
    cur.read_bytes(3)  # rsvd
    count = cur.read("I")
    if ros_version == 2 and count:
        cur._align(4)
    stride = _CDR_POINT_STRIDE if ros_version == 2 else _POINT_SIZE
    needed = cur.pos + (count - 1) * stride + _POINT_SIZE if count else cur.pos
    if needed > len(view):
        raise MalformedCustomMsgError(
            f"{what}: truncated: {count} points need {needed} bytes, message has {len(view)}"
        )
    dtype = point_dtype(order == ">")
    points = np.ndarray(shape=(count,), dtype=dtype, buffer=view, offset=cur.pos, strides=(stride,))
    return CustomMsgData(sec, nanosec, frame_id, timebase, point_num, lidar_id, points)


def custom_msg_to_decoded(data: CustomMsgData, sensor: str) -> DecodedCustomMsg:
    """A parsed CustomMsg as a :class:`Frame` (non-finite points dropped).

    ``Frame.stamp`` is the header stamp; ``point_time`` is ``timebase + offset_time``
    relative to it, in seconds (``offset_time`` alone if ``timebase`` is 0).
    """
    pts = data.points
    xyz = np.empty((pts.shape[0], 3), dtype=np.float32)
    xyz[:, 0], xyz[:, 1], xyz[:, 2] = pts["x"], pts["y"], pts["z"]
    keep = finite_rows(xyz)
    n_kept = int(np.count_nonzero(keep))
    if n_kept != len(keep):
        xyz, pts = xyz[keep], pts[keep]
    stamp_ns = data.sec * 1_000_000_000 + data.nanosec
    base = 0 if data.timebase == 0 else data.timebase - stamp_ns  # exact (Python ints)
    point_time = (pts["offset_time"].astype(np.float64) + base) * 1e-9
    frame = Frame(
        stamp=data.stamp,
        sensor=sensor,
        xyz=xyz,
        intensity=pts["reflectivity"].astype(np.float32),
        point_time=point_time,
    )
    return DecodedCustomMsg(
        frame,
        int(len(keep)),
        int(len(keep) - n_kept),
        data.timebase,
        data.lidar_id,
        data.frame_id,
        np.array(pts["tag"]),
        np.array(pts["line"]),
    )


def decode_custom_msg(
    raw: Any, sensor: str, ros_version: int = 2, what: str = "CustomMsg"
) -> DecodedCustomMsg:
    """Serialized CustomMsg bytes -> :class:`DecodedCustomMsg` (see :func:`parse_custom_msg`)."""
    return custom_msg_to_decoded(parse_custom_msg(raw, ros_version, what), sensor)


def custom_msg_to_frame(raw: Any, sensor: str, ros_version: int = 2) -> Frame:
    """Serialized CustomMsg bytes -> :class:`Frame`."""
    return decode_custom_msg(raw, sensor, ros_version).frame


def encode_custom_msg(
    frame: Frame,
    ros_version: int = 2,
    frame_id: str = "livox_frame",
    lidar_id: int = 0,
    tag: Any = 0,
    line: Any = 0,
    seq: int = 0,
) -> bytes:
    """Serialize ``frame`` as a CustomMsg (ROS 2 little-endian CDR with header, or ROS 1).

    ``timebase`` is the time of the earliest point (the frame stamp when there is no
    per-point time); ``offset_time`` = point time - timebase in ns. Reflectivity is the
    frame's intensity clipped to 0..255 (0 if absent).
    """
    n = len(frame)
    sec, nanosec = seconds_to_stamp(frame.stamp, MAX_ROS1_SEC if ros_version == 1 else MAX_ROS2_SEC)
    stamp_ns = sec * 1_000_000_000 + nanosec
    rel_ns = (
        np.zeros(n, np.int64)
        if frame.point_time is None
        else np.round(frame.point_time * 1e9).astype(np.int64)
    )
    first = int(rel_ns.min()) if n else 0
    offsets = rel_ns - first
    if n and int(offsets.max()) >= 2**32:
        raise InputError(f"frame at {frame.stamp}: point times span more than 4.29 s (uint32 ns)")
    timebase = stamp_ns + first
    points = np.zeros(n, dtype=point_dtype())
    points["offset_time"] = offsets
    points["x"], points["y"], points["z"] = frame.xyz[:, 0], frame.xyz[:, 1], frame.xyz[:, 2]
    if frame.intensity is not None:
        points["reflectivity"] = np.clip(np.round(frame.intensity), 0, 255)
    points["tag"], points["line"] = tag, line
    fid = frame_id.encode()
    if ros_version == 1:
        head = struct.pack("<III", seq, sec, nanosec) + struct.pack("<I", len(fid)) + fid
        head += struct.pack("<QIB3xI", timebase, n, lidar_id, n)
        return head + points.tobytes()
    if ros_version != 2:
        raise ValueError(f"ros_version must be 1 or 2, got {ros_version}")
    out = bytearray(b"\x00\x01\x00\x00")
    out += struct.pack("<iI", sec, nanosec)
    out += struct.pack("<I", len(fid) + 1) + fid + b"\0"

    def pad(size: int) -> None:
        out.extend(b"\0" * (-(len(out) - 4) % size))

    pad(8)
    out += struct.pack("<Q", timebase)
    out += struct.pack("<IB3x", n, lidar_id)
    pad(4)
    out += struct.pack("<I", n)
    if n:
        base = point_dtype()
        strided = np.zeros(
            n,
            dtype=np.dtype(
                {
                    "names": list(base.names),
                    "formats": [base.fields[f][0] for f in base.names],
                    "offsets": [base.fields[f][1] for f in base.names],
                    "itemsize": _CDR_POINT_STRIDE,
                }
            ),
        )
        for name in base.names:
            strided[name] = points[name]
        out += strided.tobytes()[:-1]  # CDR: no padding after the last element
    return bytes(out)
