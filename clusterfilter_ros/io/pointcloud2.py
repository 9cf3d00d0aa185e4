"""sensor_msgs/PointCloud2 <-> :class:`Frame`, for any field layout, without ROS.

Works on anything with PointCloud2's attributes (``header.stamp.sec/nanosec``,
``height``, ``width``, ``fields[*].name/offset/datatype/count``, ``is_bigendian``,
``point_step``, ``row_step``, ``data``): rclpy messages, rosbags messages (ROS 1 or 2),
or :class:`CloudMessage`. Decoding builds one numpy structured dtype from the fields and
views the bytes through it (no per-point Python code), so padding inside a point
(``point_step`` larger than the fields), padding at the end of each row (``row_step``),
organised clouds (``height > 1``) and big-endian data all work.

Writing produces the livox_ros_driver2 layout (``xfer_format`` 0) by default::

    x, y, z, intensity  float32 at 0, 4, 8, 12
    tag, line           uint8   at 16, 17
    timestamp           float64 at 18   (absolute time of each point in nanoseconds)
    point_step 26

or plain ``xyz`` float32 (point_step 12) / ``xyzi`` (16).
"""

from __future__ import annotations

import array
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from decimal import Decimal
from typing import Any

import numpy as np

from clusterfilter_ros.core.frame import Frame
from clusterfilter_ros.errors import InputError

#: PointField datatype code -> numpy type (little-endian form; byte order set per message).
DATATYPES: dict[int, np.dtype] = {
    1: np.dtype("i1"),  # INT8
    2: np.dtype("u1"),  # UINT8
    3: np.dtype("<i2"),  # INT16
    4: np.dtype("<u2"),  # UINT16
    5: np.dtype("<i4"),  # INT32
    6: np.dtype("<u4"),  # UINT32
    7: np.dtype("<f4"),  # FLOAT32
    8: np.dtype("<f8"),  # FLOAT64
}
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)

#: Field names read as intensity, in order of preference.
INTENSITY_FIELDS = ("intensity", "reflectivity", "i")
#: Field names read as per-point time, in order of preference.
TIME_FIELDS = ("timestamp", "offset_time", "time", "t")
#: A reading of per-point time fits if the median point lies this close (s) to the stamp.
_MAX_POINT_TIME_S = 1.0
#: Largest point_step accepted (numpy's itemsize is a C int; real clouds use < 100 bytes).
_MAX_POINT_STEP = 2**31 - 1


class MalformedCloudError(InputError):
    """A PointCloud2 whose fields, sizes or data length do not fit together."""


@dataclass(frozen=True)
class FieldSpec:
    """One ``sensor_msgs/PointField``: name, byte offset in the point, type code, count."""

    name: str
    offset: int
    datatype: int
    count: int = 1


#: livox_ros_driver2 PointCloud2 layout (xfer_format 0).
LIVOX_FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("x", 0, FLOAT32),
    FieldSpec("y", 4, FLOAT32),
    FieldSpec("z", 8, FLOAT32),
    FieldSpec("intensity", 12, FLOAT32),
    FieldSpec("tag", 16, UINT8),
    FieldSpec("line", 17, UINT8),
    FieldSpec("timestamp", 18, FLOAT64),
)
LIVOX_POINT_STEP = 26
XYZ_FIELDS: tuple[FieldSpec, ...] = LIVOX_FIELDS[:3]
XYZI_FIELDS: tuple[FieldSpec, ...] = LIVOX_FIELDS[:4]
#: Layout name -> (fields, point_step) for :func:`frame_to_pointcloud2_fields`.
LAYOUTS: dict[str, tuple[tuple[FieldSpec, ...], int]] = {
    "livox": (LIVOX_FIELDS, LIVOX_POINT_STEP),
    "xyz": (XYZ_FIELDS, 12),
    "xyzi": (XYZI_FIELDS, 16),
}


@dataclass
class Stamp:
    """``builtin_interfaces/Time``-like stamp."""

    sec: int = 0
    nanosec: int = 0


@dataclass
class Header:
    """``std_msgs/Header``-like header."""

    stamp: Stamp = field(default_factory=Stamp)
    frame_id: str = ""


@dataclass
class CloudMessage:
    """A plain-Python PointCloud2 (same attribute names), e.g. for tests without ROS."""

    header: Header
    height: int
    width: int
    fields: list[FieldSpec]
    is_bigendian: bool
    point_step: int
    row_step: int
    data: bytes
    is_dense: bool = True


@dataclass(frozen=True)
class DecodedCloud:
    """Result of :func:`decode_pointcloud2`.

    Attributes:
        frame: the finite points as a :class:`Frame`.
        n_points: points in the message (``width * height``).
        n_dropped_nonfinite: points dropped because x, y or z was NaN/Inf.
        time_field: name of the field used for ``frame.point_time`` (None if absent).
        time_unit: how that field was read: ``"ns-absolute"``, ``"s-absolute"``,
            ``"ns-relative"``, ``"s-relative"`` (None if absent), or ``"unrecognised"``
            (field present but fits no reading; ``frame.point_time`` is then None).
    """

    frame: Frame
    n_points: int
    n_dropped_nonfinite: int
    time_field: str | None = None
    time_unit: str | None = None


def stamp_to_seconds(stamp: Any) -> float:
    """Seconds from a ``builtin_interfaces/Time`` (``sec``/``nanosec``) or ROS 1 time."""
    sec = getattr(stamp, "sec", None)
    if sec is None:
        sec = getattr(stamp, "secs", 0)
    nanosec = getattr(stamp, "nanosec", None)
    if nanosec is None:
        nanosec = getattr(stamp, "nsecs", 0)
    return float(sec) + float(nanosec) * 1e-9


#: Largest ``sec`` of a ROS 1 time (uint32) and of a ROS 2 time (int32).
MAX_ROS1_SEC = 2**32 - 1
MAX_ROS2_SEC = 2**31 - 1


def seconds_to_stamp(
    seconds: float, max_sec: int = MAX_ROS1_SEC, min_sec: int = 0
) -> tuple[int, int]:
    """``(sec, nanosec)`` for a time in seconds, nanoseconds rounded, carry handled.

    Goes through the float's shortest decimal form, so ``1706255621.600227`` gives
    nanosec ``600227000`` (not the binary float's ``600227117``). A time that is not
    finite or whose ``sec`` is outside ``min_sec .. max_sec`` (:data:`MAX_ROS2_SEC` for
    ROS 2 messages) is an :class:`InputError`.
    """
    if not np.isfinite(seconds):
        raise InputError(f"cannot make a ROS stamp from {seconds!r}")
    total_ns = int((Decimal(repr(float(seconds))) * 1_000_000_000).to_integral_value())
    sec, nanosec = divmod(int(total_ns), 1_000_000_000)
    if not min_sec <= sec <= max_sec:
        raise InputError(
            f"cannot make a ROS stamp from {seconds!r}: seconds must be in {min_sec} .. {max_sec}"
        )
    return sec, nanosec


def _field_specs(fields: Iterable[Any]) -> list[FieldSpec]:
    return [
        FieldSpec(str(f.name), int(f.offset), int(f.datatype), int(getattr(f, "count", 1) or 1))
        for f in fields
    ]


def cloud_dtype(fields: Iterable[Any], point_step: int, is_bigendian: bool = False) -> np.dtype:
    """The numpy structured dtype of one point (itemsize ``point_step``).

    Raises :class:`MalformedCloudError` for unknown type codes, duplicate names or fields
    reaching beyond ``point_step``. Fields with ``count > 1`` become sub-arrays.
    """
    specs = _field_specs(fields)
    if point_step <= 0 or point_step > _MAX_POINT_STEP:
        raise MalformedCloudError(f"point_step is {point_step}, must be 1..{_MAX_POINT_STEP}")
    names, formats, offsets = [], [], []
    for spec in specs:
        if spec.datatype not in DATATYPES:
            raise MalformedCloudError(f"field {spec.name!r} has unknown datatype {spec.datatype}")
        if spec.name in names:
            raise MalformedCloudError(f"field {spec.name!r} appears twice")
        if spec.count < 1:
            raise MalformedCloudError(f"field {spec.name!r} has count {spec.count}")
        base = DATATYPES[spec.datatype]
        size = base.itemsize * spec.count  # checked before numpy sees it (C int limits)
        if spec.offset < 0 or spec.offset + size > point_step:
            raise MalformedCloudError(
                f"field {spec.name!r} at offset {spec.offset} ({size} bytes) "
                f"lies beyond point_step {point_step}"
            )
        base = base.newbyteorder(">") if is_bigendian and base.itemsize > 1 else base
        fmt = np.dtype((base, (spec.count,))) if spec.count > 1 else base
        names.append(spec.name)
        formats.append(fmt)
        offsets.append(spec.offset)
    return np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step}
    )


def _data_bytes(data: Any) -> np.ndarray:
    """``msg.data`` (bytes, array.array, numpy array, list) as a flat uint8 array (no copy)."""
    if isinstance(data, np.ndarray):
        return data.reshape(-1).view(np.uint8) if data.dtype.itemsize == 1 else data.view(np.uint8)
    if isinstance(data, (bytes, bytearray, memoryview, array.array)):
        return np.frombuffer(data, dtype=np.uint8)
    return np.asarray(data, dtype=np.uint8)


def cloud_to_structured(msg: Any) -> np.ndarray:
    """The points of a PointCloud2 as a flat structured array (one record per point).

    Row padding (``row_step > width * point_step``) is skipped; the result is a view on
    the message's bytes when there is none.
    """
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    dtype = cloud_dtype(msg.fields, point_step, bool(msg.is_bigendian))
    data = _data_bytes(msg.data)
    if height < 0 or width < 0:
        raise MalformedCloudError(f"height {height} / width {width} must not be negative")
    n = height * width
    if n == 0:
        return np.empty(0, dtype=dtype)
    if row_step < width * point_step:
        raise MalformedCloudError(
            f"row_step {row_step} is smaller than width {width} x point_step {point_step}"
        )
    if data.size != height * row_step:
        raise MalformedCloudError(
            f"data has {data.size} bytes, expected height {height} x row_step {row_step} "
            f"= {height * row_step}"
        )
    if row_step == width * point_step:
        return np.frombuffer(data, dtype=dtype, count=n)
    rows = data.reshape(height, row_step)[:, : width * point_step]
    return np.ascontiguousarray(rows).view(dtype).reshape(n)


def field_names(msg: Any) -> list[str]:
    """Names of the fields of a PointCloud2."""
    return [str(f.name) for f in msg.fields]


def cloud_fields_to_arrays(
    msg: Any, names: Iterable[str] | None = None, dtype: np.dtype | type | None = None
) -> dict[str, np.ndarray]:
    """Selected fields (default all) as plain arrays in native byte order, one per name.

    With ``dtype`` every array is converted to it. Missing names raise
    :class:`MalformedCloudError`.
    """
    points = cloud_to_structured(msg)
    wanted = list(points.dtype.names or ()) if names is None else list(names)
    missing = [n for n in wanted if n not in (points.dtype.names or ())]
    if missing:
        raise MalformedCloudError(
            f"no field(s) {', '.join(missing)} (fields: {', '.join(field_names(msg)) or 'none'})"
        )
    out = {}
    for name in wanted:
        col = points[name]
        target = col.dtype.newbyteorder("=") if dtype is None else np.dtype(dtype)
        out[name] = col.astype(target)
    return out


def finite_rows(xyz: np.ndarray) -> np.ndarray:
    """Mask of (N, 3) rows whose coordinates are all finite.

    Three column tests are ~10x faster than ``np.isfinite(xyz).all(axis=1)`` (a
    reduction over a length-3 axis is slow in numpy).
    """
    return np.isfinite(xyz[:, 0]) & np.isfinite(xyz[:, 1]) & np.isfinite(xyz[:, 2])


def _point_time_seconds(
    values: np.ndarray, stamp: float, field_name: str
) -> tuple[np.ndarray | None, str]:
    """Per-point time in seconds relative to ``stamp``, and the unit that was detected.

    Three readings are tried: absolute nanoseconds, absolute seconds (livox_ros_driver2
    writes absolute ns in ``timestamp``), and an offset from the stamp (integers are
    nanoseconds; floats are seconds if all lie within 10 s, else nanoseconds). A reading
    fits if the median point lies within :data:`_MAX_POINT_TIME_S` of the stamp. Fields
    named ``timestamp`` prefer the absolute readings, others the offset. If none fits,
    the time is ``None`` and the unit ``"unrecognised"``.
    """
    v = values.astype(np.float64)
    if v.size == 0:
        return v, "s-relative"
    sample = v[:: max(1, v.size // 1024)]  # the unit is decided on <= ~2k points
    finite = sample[np.isfinite(sample)]
    if finite.size == 0:
        return None, "unrecognised"
    median = float(np.median(finite))
    if values.dtype.kind in "iu" or float(np.max(np.abs(finite))) > 10.0:
        relative = ("ns-relative", 1e-9, 0.0)
    else:
        relative = ("s-relative", 1.0, 0.0)
    readings = [("ns-absolute", 1e-9, stamp), ("s-absolute", 1.0, stamp)]
    readings = readings + [relative] if field_name == "timestamp" else [relative] + readings
    for unit, scale, origin in readings:
        if abs(median * scale - origin) <= _MAX_POINT_TIME_S:
            if origin == 0.0:
                return v * scale, unit
            if scale == 1.0:
                return v - origin, unit
            return (v - origin * 1e9) * scale, unit
    return None, "unrecognised"


def decode_pointcloud2(msg: Any, sensor: str) -> DecodedCloud:
    """Decode a PointCloud2 into a :class:`Frame` with counts of what was dropped.

    x, y, z become float32; intensity comes from the first of :data:`INTENSITY_FIELDS`
    present; per-point time from the first of :data:`TIME_FIELDS` present, converted to
    seconds relative to the header stamp. Points with a non-finite coordinate are dropped.
    """
    points = cloud_to_structured(msg)
    names = points.dtype.names or ()
    missing = [n for n in ("x", "y", "z") if n not in names]
    if missing:
        raise MalformedCloudError(
            f"no {'/'.join(missing)} field (fields: {', '.join(names) or 'none'})"
        )
    stamp = stamp_to_seconds(msg.header.stamp)
    n = points.shape[0]
    xyz = np.empty((n, 3), dtype=np.float32)
    # float64 values beyond float32's range become Inf (and are dropped) without warnings.
    with np.errstate(over="ignore", invalid="ignore"):
        for i, axis in enumerate("xyz"):
            if points.dtype[axis].shape:
                raise MalformedCloudError(f"field {axis!r} has count {points.dtype[axis].shape[0]}")
            xyz[:, i] = points[axis]
        keep = finite_rows(xyz)
        n_kept = int(np.count_nonzero(keep))
        all_kept = n_kept == n
        intensity = None
        name = next((f for f in INTENSITY_FIELDS if f in names and not points.dtype[f].shape), None)
        if name is not None:
            intensity = points[name].astype(np.float32)
            intensity = intensity if all_kept else intensity[keep]
        point_time, time_field, time_unit = None, None, None
        time_field = next(
            (f for f in TIME_FIELDS if f in names and not points.dtype[f].shape), None
        )
        if time_field is not None:
            raw = points[time_field]
            point_time, time_unit = _point_time_seconds(
                raw if all_kept else raw[keep], stamp, time_field
            )
    frame = Frame(
        stamp=stamp,
        sensor=sensor,
        xyz=xyz if all_kept else xyz[keep],
        intensity=intensity,
        point_time=point_time,
    )
    return DecodedCloud(frame, n, n - n_kept, time_field, time_unit)


def pointcloud2_to_frame(msg: Any, sensor: str) -> Frame:
    """A PointCloud2 as a :class:`Frame` (see :func:`decode_pointcloud2`)."""
    return decode_pointcloud2(msg, sensor).frame


def pack_points(
    frame: Frame, layout: str = "livox", tag: Any = None, line: Any = None
) -> tuple[list[FieldSpec], int, np.ndarray]:
    """Pack a frame's points into a structured array: ``(fields, point_step, points)``.

    Same content as :func:`frame_to_pointcloud2_fields`, without copying to ``bytes``.

    ``layout`` is a key of :data:`LAYOUTS`. For ``livox``, missing intensity is written
    as 0, ``timestamp`` as the absolute time of each point in nanoseconds
    (``stamp + point_time``, or the frame stamp when there is no per-point time), and
    ``tag``/``line`` as given (scalars or per-point arrays, default 0).
    """
    if layout not in LAYOUTS:
        raise InputError(f"unknown PointCloud2 layout {layout!r}; choose {', '.join(LAYOUTS)}")
    specs, point_step = LAYOUTS[layout]
    dtype = cloud_dtype(specs, point_step)
    n = len(frame)
    points = np.zeros(n, dtype=dtype)
    points["x"], points["y"], points["z"] = frame.xyz[:, 0], frame.xyz[:, 1], frame.xyz[:, 2]
    if "intensity" in dtype.names and frame.intensity is not None:
        points["intensity"] = frame.intensity
    if "timestamp" in dtype.names:
        # A float field: any stamp a ROS 1 or ROS 2 header can hold.
        sec, nanosec = seconds_to_stamp(frame.stamp, MAX_ROS1_SEC, -MAX_ROS2_SEC - 1)
        stamp_ns = float(sec * 1_000_000_000 + nanosec)
        offsets = 0.0 if frame.point_time is None else np.round(frame.point_time * 1e9)
        points["timestamp"] = stamp_ns + offsets
        points["tag"] = 0 if tag is None else tag
        points["line"] = 0 if line is None else line
    return list(specs), point_step, points


def frame_to_pointcloud2_fields(
    frame: Frame, layout: str = "livox", tag: Any = None, line: Any = None
) -> tuple[list[FieldSpec], int, bytes]:
    """Pack a frame's points: ``(fields, point_step, data)`` for one PointCloud2 row.

    ``layout`` is a key of :data:`LAYOUTS`. For ``livox``, missing intensity is written
    as 0, ``timestamp`` as the absolute time of each point in nanoseconds
    (``stamp + point_time``, or the frame stamp when there is no per-point time), and
    ``tag``/``line`` as given (scalars or per-point arrays, default 0).
    """
    specs, point_step, points = pack_points(frame, layout, tag, line)
    return specs, point_step, points.tobytes()


def frame_to_cloud_message(frame: Frame, frame_id: str = "", layout: str = "livox") -> CloudMessage:
    """A ROS-free :class:`CloudMessage` holding ``frame`` (one row, header = frame stamp)."""
    specs, point_step, data = frame_to_pointcloud2_fields(frame, layout)
    sec, nanosec = seconds_to_stamp(frame.stamp)
    return CloudMessage(
        header=Header(Stamp(sec, nanosec), frame_id),
        height=1,
        width=len(frame),
        fields=specs,
        is_bigendian=False,
        point_step=point_step,
        row_step=point_step * len(frame),
        data=data,
        is_dense=True,
    )


def frame_to_pointcloud2(
    frame: Frame,
    msg_cls: type,
    field_cls: type,
    header: Any,
    layout: str = "livox",
) -> Any:
    """Build a PointCloud2 of class ``msg_cls`` (rclpy or rosbags) holding ``frame``.

    ``field_cls`` is the matching PointField class and ``header`` a ready header of the
    same message family. rclpy classes (which have ``get_fields_and_field_types``) get
    ``data`` as ``array.array('B')``; others (rosbags) as a numpy uint8 array.
    """
    specs, point_step, points = pack_points(frame, layout)
    fields = [
        field_cls(name=s.name, offset=s.offset, datatype=s.datatype, count=s.count) for s in specs
    ]
    payload: Any
    if hasattr(msg_cls, "get_fields_and_field_types"):  # rclpy: one copy into array('B')
        payload = array.array("B")
        payload.frombytes(points.view(np.uint8))
    else:  # rosbags: a uint8 view of the freshly packed points, no copy
        payload = points.view(np.uint8).reshape(-1)
    return msg_cls(
        header=header,
        height=1,
        width=len(frame),
        fields=fields,
        is_bigendian=False,
        point_step=point_step,
        row_step=point_step * len(frame),
        data=payload,
        is_dense=True,
    )


def make_pointcloud2(frame: Frame, frame_id: str = "livox_frame", layout: str = "livox") -> Any:
    """An rclpy ``sensor_msgs.msg.PointCloud2`` holding ``frame`` (needs ROS 2 messages)."""
    from builtin_interfaces.msg import Time
    from sensor_msgs.msg import PointCloud2, PointField
    from std_msgs.msg import Header as RosHeader

    # builtin_interfaces/Time.sec is an int32 (negative stamps allowed, as the node's own
    # conversion in ros/stamps.py): a cloud stamped as its input frame is always valid.
    sec, nanosec = seconds_to_stamp(frame.stamp, MAX_ROS2_SEC, -MAX_ROS2_SEC - 1)
    header = RosHeader(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)
    return frame_to_pointcloud2(frame, PointCloud2, PointField, header, layout)


def structured_to_cloud_message(
    points: np.ndarray,
    stamp: float = 0.0,
    frame_id: str = "",
    height: int = 1,
    row_padding: int = 0,
    datatypes: Mapping[str, int] | None = None,
) -> CloudMessage:
    """Build a :class:`CloudMessage` from any structured array (any layout, tests/tools).

    The array's own dtype (offsets, itemsize, byte order of its fields) defines the
    fields; ``row_padding`` extra bytes are appended after each of ``height`` rows.
    Type codes are derived from the field dtypes unless given in ``datatypes``.
    """
    dtype = points.dtype
    codes = {np.dtype(v).newbyteorder("<").str.lstrip("<|"): k for k, v in DATATYPES.items()}
    specs, big = [], None
    for name in dtype.names or ():
        fdt, offset = dtype.fields[name][:2]
        base, count = (fdt.subdtype[0], int(np.prod(fdt.subdtype[1]))) if fdt.subdtype else (fdt, 1)
        if base.itemsize > 1:
            big = base.byteorder == ">" or (base.byteorder == "=" and np.little_endian is False)
        code = (datatypes or {}).get(name) or codes[base.newbyteorder("<").str.lstrip("<|")]
        specs.append(FieldSpec(name, int(offset), int(code), count))
    n = points.shape[0]
    if height < 1 or n % height:
        raise ValueError(f"{n} points cannot form {height} rows")
    width = n // height
    row_bytes = width * dtype.itemsize
    raw = np.frombuffer(points.tobytes(), dtype=np.uint8).reshape(height, row_bytes)
    if row_padding:
        raw = np.concatenate([raw, np.full((height, row_padding), 0xAB, np.uint8)], axis=1)
    sec, nanosec = seconds_to_stamp(stamp)
    return CloudMessage(
        header=Header(Stamp(sec, nanosec), frame_id),
        height=height,
        width=width,
        fields=specs,
        is_bigendian=bool(big),
        point_step=dtype.itemsize,
        row_step=row_bytes + row_padding,
        data=raw.tobytes(),
    )
