"""Livox CustomMsg parsing from raw bytes (ROS 1 and ROS 2 CDR), cross-checked with rosbags."""

from __future__ import annotations

import numpy as np
import pytest

from clusterfilter_ros.core.frame import AVIA, MID360, Frame
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.livox import (
    CUSTOM_MSG_TYPES,
    MalformedCustomMsgError,
    decode_custom_msg,
    encode_custom_msg,
    is_custom_msg_type,
    parse_custom_msg,
)

STAMP = 1706255621.600227


def _frame(n: int, seed: int = 0) -> Frame:
    rng = np.random.default_rng(seed)
    return Frame(
        STAMP,
        MID360,
        (rng.normal(size=(n, 3)) * 40).astype(np.float32),
        intensity=rng.integers(0, 256, n).astype(np.float32),
        point_time=np.sort(rng.random(n)) * 0.1,
    )


@pytest.fixture(scope="module")
def typestores():
    rosbags_typesys = pytest.importorskip("rosbags.typesys")
    from clusterfilter_ros.io.bags import typestore_for

    assert rosbags_typesys
    return {1: typestore_for(1), 2: typestore_for(2)}


@pytest.mark.parametrize("ros_version", [1, 2])
@pytest.mark.parametrize("n", [0, 1, 7, 1000])
def test_encode_decode_round_trip(ros_version: int, n: int) -> None:
    frame = _frame(n)
    raw = encode_custom_msg(frame, ros_version, frame_id="livox_frame", lidar_id=3, line=2)
    decoded = decode_custom_msg(raw, MID360, ros_version)
    back = decoded.frame
    assert back.stamp == pytest.approx(STAMP, abs=1e-9)
    assert decoded.lidar_id == 3 and decoded.frame_id == "livox_frame"
    np.testing.assert_array_equal(back.xyz, frame.xyz)
    np.testing.assert_array_equal(back.intensity, frame.intensity)
    np.testing.assert_allclose(back.point_time, frame.point_time, atol=1e-9)
    assert (decoded.line == 2).all() and len(decoded.tag) == n


@pytest.mark.parametrize("msgtype", CUSTOM_MSG_TYPES)
@pytest.mark.parametrize("ros_version", [1, 2])
def test_bytes_match_rosbags_serialisation(typestores, msgtype: str, ros_version: int) -> None:
    """Our encoder and parser agree byte for byte with rosbags' generic (de)serialiser."""
    ts = typestores[ros_version]
    frame = _frame(33, seed=ros_version)
    raw = encode_custom_msg(frame, ros_version, frame_id="avia_frame", lidar_id=1, tag=16)
    if ros_version == 2:
        msg = ts.deserialize_cdr(raw, msgtype)
        again = bytes(ts.serialize_cdr(msg, msgtype))
    else:
        msg = ts.deserialize_ros1(raw, msgtype)
        again = bytes(ts.serialize_ros1(msg, msgtype))
    assert again == raw
    assert msg.header.frame_id == "avia_frame" and msg.point_num == 33 and msg.lidar_id == 1
    assert [msg.points[5].x, msg.points[5].tag] == [frame.xyz[5, 0], 16]
    assert msg.timebase + msg.points[32].offset_time == pytest.approx(
        (STAMP + frame.point_time[32]) * 1e9, abs=300
    )
    parsed = parse_custom_msg(again, ros_version)
    np.testing.assert_array_equal(parsed.points["y"], frame.xyz[:, 1])


def test_big_endian_cdr(typestores) -> None:
    """A big-endian CDR message (encapsulation 00 00) parses with the same values."""
    ts = typestores[2]
    frame = _frame(5)
    msgtype = CUSTOM_MSG_TYPES[1]
    msg = ts.deserialize_cdr(encode_custom_msg(frame, 2), msgtype)
    raw_be = bytes(ts.serialize_cdr(msg, msgtype, little_endian=False))
    assert raw_be[:2] == b"\x00\x00"
    back = decode_custom_msg(raw_be, AVIA, 2).frame
    np.testing.assert_array_equal(back.xyz, frame.xyz)


def test_nonfinite_points_dropped() -> None:
    xyz = _frame(6).xyz.copy()
    xyz[[1, 4], 2] = np.nan
    frame = Frame(STAMP, AVIA, xyz, point_time=np.arange(6) * 0.01)
    decoded = decode_custom_msg(encode_custom_msg(frame, 2), AVIA, 2)
    assert decoded.n_points == 6 and decoded.n_dropped_nonfinite == 2
    np.testing.assert_allclose(decoded.frame.point_time, [0, 0.02, 0.03, 0.05], atol=1e-9)


@pytest.mark.parametrize("ros_version", [1, 2])
def test_truncated_message(ros_version: int) -> None:
    raw = encode_custom_msg(_frame(10), ros_version)
    for cut in (3, 30, len(raw) - 1):
        with pytest.raises(MalformedCustomMsgError, match="truncated|too short") as info:
            parse_custom_msg(raw[:cut], ros_version, what="bag.db3 /livox/lidar")
        assert isinstance(info.value, InputError)
        assert "\n" not in str(info.value)


def test_type_names() -> None:
    assert is_custom_msg_type("livox_ros_driver2/msg/CustomMsg")
    assert is_custom_msg_type("livox_ros_driver/CustomMsg")
    assert not is_custom_msg_type("sensor_msgs/msg/PointCloud2")
    assert not is_custom_msg_type("other_pkg/msg/CustomMsg")
