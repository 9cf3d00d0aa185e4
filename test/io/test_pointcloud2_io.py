"""PointCloud2 decoding/encoding for many field layouts, and rclpy interoperability."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clusterfilter_ros.core.frame import AVIA, MID360, Frame
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.pointcloud2 import (
    FLOAT32,
    LIVOX_POINT_STEP,
    CloudMessage,
    FieldSpec,
    Header,
    MalformedCloudError,
    Stamp,
    cloud_fields_to_arrays,
    decode_pointcloud2,
    frame_to_cloud_message,
    frame_to_pointcloud2_fields,
    pointcloud2_to_frame,
    seconds_to_stamp,
    structured_to_cloud_message,
)

STAMP = 1706255621.600227


def _frame(n: int = 500, with_time: bool = True, seed: int = 0) -> Frame:
    rng = np.random.default_rng(seed)
    return Frame(
        stamp=STAMP,
        sensor=AVIA,
        xyz=(rng.normal(size=(n, 3)) * 60).astype(np.float32),
        intensity=rng.integers(0, 255, n).astype(np.float32),
        point_time=np.sort(rng.random(n)) * 0.1 if with_time else None,
    )


def test_livox_layout_round_trip() -> None:
    frame = _frame()
    msg = frame_to_cloud_message(frame, "livox_frame")
    assert msg.point_step == LIVOX_POINT_STEP == 26
    assert len(msg.data) == 26 * len(frame)
    assert [(f.name, f.offset, f.datatype) for f in msg.fields] == [
        ("x", 0, 7),
        ("y", 4, 7),
        ("z", 8, 7),
        ("intensity", 12, 7),
        ("tag", 16, 2),
        ("line", 17, 2),
        ("timestamp", 18, 8),
    ]
    decoded = decode_pointcloud2(msg, AVIA)
    assert decoded.time_unit == "ns-absolute" and decoded.n_dropped_nonfinite == 0
    back = decoded.frame
    assert back.stamp == pytest.approx(STAMP, abs=1e-9)
    np.testing.assert_array_equal(back.xyz, frame.xyz)
    np.testing.assert_array_equal(back.intensity, frame.intensity)
    np.testing.assert_allclose(back.point_time, frame.point_time, atol=1e-6)
    # absolute nanoseconds as livox_ros_driver2 writes them
    ts = cloud_fields_to_arrays(msg, ["timestamp"])["timestamp"]
    assert ts[0] == pytest.approx((STAMP + frame.point_time[0]) * 1e9, abs=1e3)


def test_livox_without_point_time_uses_stamp() -> None:
    back = pointcloud2_to_frame(frame_to_cloud_message(_frame(50, with_time=False)), AVIA)
    np.testing.assert_allclose(back.point_time, 0.0, atol=1e-6)


@pytest.mark.parametrize("layout, step", [("xyz", 12), ("xyzi", 16)])
def test_plain_layouts(layout: str, step: int) -> None:
    frame = _frame(64)
    fields, point_step, data = frame_to_pointcloud2_fields(frame, layout)
    assert point_step == step and len(data) == step * 64
    back = pointcloud2_to_frame(frame_to_cloud_message(frame, layout=layout), MID360)
    np.testing.assert_array_equal(back.xyz, frame.xyz)
    assert back.point_time is None
    assert (back.intensity is None) == (layout == "xyz")


def _custom_points(n: int, dtype: np.dtype, rng: np.random.Generator) -> np.ndarray:
    points = np.zeros(n, dtype=dtype)
    for name in ("x", "y", "z"):
        points[name] = rng.normal(size=n) * 30
    return points


@pytest.mark.parametrize("big_endian", [False, True])
@pytest.mark.parametrize("height, row_padding", [(1, 0), (4, 0), (4, 7), (1, 3)])
def test_any_layout_float64_padding_endianness(
    big_endian: bool, height: int, row_padding: int
) -> None:
    rng = np.random.default_rng(height + row_padding)
    e = ">" if big_endian else "<"
    dtype = np.dtype(
        {
            "names": ["z", "x", "y", "reflectivity", "offset_time", "ring"],
            "formats": [e + "f8", e + "f8", e + "f8", "u1", e + "u4", e + "u2"],
            "offsets": [0, 8, 16, 24, 28, 34],
            "itemsize": 40,  # 4 bytes of padding inside each point
        }
    )
    points = _custom_points(48, dtype, rng)
    points["reflectivity"] = rng.integers(0, 255, 48)
    points["offset_time"] = np.arange(48) * 1000  # ns offsets
    msg = structured_to_cloud_message(points, STAMP, height=height, row_padding=row_padding)
    assert msg.is_bigendian == big_endian
    assert msg.row_step == 40 * (48 // height) + row_padding
    decoded = decode_pointcloud2(msg, MID360)
    frame = decoded.frame
    expected = np.stack([points["x"], points["y"], points["z"]], axis=1).astype(np.float32)
    np.testing.assert_array_equal(frame.xyz, expected)
    np.testing.assert_array_equal(frame.intensity, points["reflectivity"].astype(np.float32))
    assert decoded.time_field == "offset_time" and decoded.time_unit == "ns-relative"
    np.testing.assert_allclose(frame.point_time, np.arange(48) * 1e-6)
    arrays = cloud_fields_to_arrays(msg, ["ring", "x"])
    assert arrays["ring"].dtype == np.dtype("u2") and arrays["ring"].dtype.isnative
    np.testing.assert_array_equal(arrays["x"], points["x"])


def test_relative_seconds_float_time_and_count_field() -> None:
    rng = np.random.default_rng(5)
    dtype = np.dtype(
        {
            "names": ["x", "y", "z", "time", "rgb"],
            "formats": ["<f4", "<f4", "<f4", "<f4", ("u1", 3)],
        }
    )
    points = _custom_points(10, dtype, rng)
    points["time"] = np.linspace(0, 0.09, 10)
    msg = structured_to_cloud_message(points, STAMP)
    assert [f.count for f in msg.fields] == [1, 1, 1, 1, 3]
    decoded = decode_pointcloud2(msg, AVIA)
    assert decoded.time_unit == "s-relative"
    np.testing.assert_allclose(decoded.frame.point_time, points["time"], rtol=1e-6)


def test_nonfinite_points_dropped_and_counted() -> None:
    frame = _frame(20)
    msg = frame_to_cloud_message(frame)
    points = np.frombuffer(msg.data, dtype=np.uint8).copy()
    x = points.reshape(20, 26)[:, 0:4].copy().view("<f4")
    x[[2, 7]] = np.nan
    x[11] = np.inf
    points.reshape(20, 26)[:, 0:4] = x.view(np.uint8)
    msg.data = points.tobytes()
    decoded = decode_pointcloud2(msg, AVIA)
    assert decoded.n_points == 20 and decoded.n_dropped_nonfinite == 3
    keep = np.setdiff1d(np.arange(20), [2, 7, 11])
    np.testing.assert_array_equal(decoded.frame.xyz, frame.xyz[keep])
    np.testing.assert_array_equal(decoded.frame.intensity, frame.intensity[keep])
    np.testing.assert_allclose(decoded.frame.point_time, frame.point_time[keep], atol=1e-6)


def test_empty_cloud() -> None:
    empty = Frame(STAMP, AVIA, np.empty((0, 3), np.float32))
    back = decode_pointcloud2(frame_to_cloud_message(empty), AVIA)
    assert len(back.frame) == 0 and back.n_points == 0


def _malformed(kind: str) -> CloudMessage:
    msg = frame_to_cloud_message(_frame(10))
    if kind == "no_z":
        msg.fields = [f for f in msg.fields if f.name != "z"]
    elif kind == "short_data":
        msg.data = msg.data[:-5]
    elif kind == "long_data":
        msg.data = msg.data + b"\0" * 26
    elif kind == "offset":
        msg.fields = [*msg.fields[:-1], FieldSpec("timestamp", 22, 8)]
    elif kind == "datatype":
        msg.fields = [*msg.fields[:-1], FieldSpec("timestamp", 18, 9)]
    elif kind == "row_step":
        msg.row_step = 100
    elif kind == "duplicate":
        msg.fields = [*msg.fields, FieldSpec("x", 0, FLOAT32)]
    return msg


@pytest.mark.parametrize(
    "kind, match",
    [
        ("no_z", "no z field"),
        ("short_data", "data has 255 bytes"),
        ("long_data", "data has 286 bytes"),
        ("offset", "beyond point_step 26"),
        ("datatype", "unknown datatype 9"),
        ("row_step", "row_step 100 is smaller"),
        ("duplicate", "appears twice"),
    ],
)
def test_malformed_messages(kind: str, match: str) -> None:
    with pytest.raises(MalformedCloudError, match=match) as info:
        decode_pointcloud2(_malformed(kind), AVIA)
    assert isinstance(info.value, InputError) and "\n" not in str(info.value)


def test_stamp_conversion() -> None:
    assert seconds_to_stamp(1.9999999999) == (2, 0)
    assert seconds_to_stamp(STAMP) == (1706255621, 600227000)
    assert seconds_to_stamp(4294967295.5) == (4294967295, 500000000)
    for bad in (-0.5, 4294967296.0, 1706255599999223000.0):
        with pytest.raises(InputError, match=r"cannot make a ROS stamp .*0 \.\. 4294967295"):
            seconds_to_stamp(bad)
    with pytest.raises(InputError, match=r"0 \.\. 2147483647"):
        seconds_to_stamp(2**31 + 0.5, max_sec=2**31 - 1)
    msg = CloudMessage(Header(Stamp(5, 500_000_000)), 0, 0, [], False, 26, 0, b"")
    with pytest.raises(MalformedCloudError, match="no x/y/z"):
        decode_pointcloud2(msg, AVIA)


def test_rclpy_deserialises_our_message_bit_identical() -> None:
    pytest.importorskip("sensor_msgs.msg")
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import PointCloud2

    from clusterfilter_ros.io.pointcloud2 import make_pointcloud2

    frame = _frame(2000, seed=9)
    for layout in ("livox", "xyz"):
        msg = make_pointcloud2(frame, "livox_frame", layout=layout)
        raw = serialize_message(msg)
        again = deserialize_message(raw, PointCloud2)
        assert bytes(again.data) == bytes(msg.data) == frame_to_pointcloud2_fields(frame, layout)[2]
        assert again.header.frame_id == "livox_frame"
        assert (again.header.stamp.sec, again.header.stamp.nanosec) == seconds_to_stamp(STAMP)
        back = pointcloud2_to_frame(again, AVIA)
        np.testing.assert_array_equal(back.xyz, frame.xyz)
        if layout == "livox":
            np.testing.assert_array_equal(back.intensity, frame.intensity)
            np.testing.assert_allclose(back.point_time, frame.point_time, atol=1e-6)


@settings(max_examples=40, deadline=None)
@given(
    order=st.permutations(["x", "y", "z", "intensity"]),
    xyz_type=st.sampled_from(["f4", "f8"]),
    extra_pad=st.integers(0, 9),
    row_padding=st.integers(0, 6),
    height=st.sampled_from([1, 2, 3]),
    width=st.integers(0, 12),
    big_endian=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_any_packed_layout_property(
    order: list[str],
    xyz_type: str,
    extra_pad: int,
    row_padding: int,
    height: int,
    width: int,
    big_endian: bool,
    seed: int,
) -> None:
    """Any field order, width, padding and byte order decodes to the same points."""
    e = ">" if big_endian else "<"
    formats = {"x": xyz_type, "y": xyz_type, "z": xyz_type, "intensity": "u2"}
    offsets, pos = [], 0
    for name in order:
        offsets.append(pos)
        pos += np.dtype(formats[name]).itemsize
    dtype = np.dtype(
        {
            "names": list(order),
            "formats": [e + formats[n] for n in order],
            "offsets": offsets,
            "itemsize": pos + extra_pad,
        }
    )
    rng = np.random.default_rng(seed)
    points = np.zeros(height * width, dtype=dtype)
    for name in "xyz":
        points[name] = rng.normal(size=points.shape[0]) * 100
    points["intensity"] = rng.integers(0, 65535, points.shape[0])
    msg = structured_to_cloud_message(points, STAMP, height=height, row_padding=row_padding)
    frame = pointcloud2_to_frame(msg, AVIA)
    expected = np.stack([points[a] for a in "xyz"], axis=1).astype(np.float32)
    np.testing.assert_array_equal(frame.xyz, expected)
    np.testing.assert_array_equal(frame.intensity, points["intensity"].astype(np.float32))
