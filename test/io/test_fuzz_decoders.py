"""Property-based fuzzing of the PointCloud2 and Livox CustomMsg decoders.

Two kinds of input for each decoder:

- *well-formed* messages with random layouts (field order, types, padding inside the
  point and after each row, organised clouds, big-endian data, NaN/Inf/huge values):
  the decoder must return exactly the finite points a byte-by-byte ``struct`` reference
  reads from the message;
- *malformed* messages (random field tables, point_step/row_step/width/height that do
  not fit the data, random or truncated or bit-flipped bytes): the decoder may only
  raise its documented error (:class:`MalformedCloudError` /
  :class:`MalformedCustomMsgError`, both :class:`InputError`), never anything else.

The number of examples each property ran is printed to the terminal (also without -s);
``CLUSTERFILTER_FUZZ_EXAMPLES=5000`` runs a deeper search than CI's 300 per property.
"""

from __future__ import annotations

import os
import struct
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clusterfilter_ros.core.frame import MID360, Frame
from clusterfilter_ros.io.livox import (
    MalformedCustomMsgError,
    decode_custom_msg,
    encode_custom_msg,
)
from clusterfilter_ros.io.pointcloud2 import (
    CloudMessage,
    DecodedCloud,
    FieldSpec,
    Header,
    MalformedCloudError,
    Stamp,
    decode_pointcloud2,
)

#: PointField datatype -> struct format character and size.
STRUCT_CODES = {1: "b", 2: "B", 3: "h", 4: "H", 5: "i", 6: "I", 7: "f", 8: "d"}
SPECIAL_FLOATS = [float("nan"), float("inf"), float("-inf"), 0.0, -0.0, 1e30, -3.4e38, 1e-40]
#: Examples per property; CLUSTERFILTER_FUZZ_EXAMPLES raises it for a deeper local run.
EXAMPLES = int(os.environ.get("CLUSTERFILTER_FUZZ_EXAMPLES", "300"))
FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

#: Examples run per property, reported at the end of each test.
_counts: dict[str, int] = {}


def _report(capsys: pytest.CaptureFixture[str], name: str, extra: str = "") -> None:
    with capsys.disabled():
        print(f"\n[fuzz] {name}: {_counts.get(name, 0)} examples{extra}")


def _count(name: str) -> None:
    _counts[name] = _counts.get(name, 0) + 1


# --------------------------------------------------------------------------- PointCloud2
OPTIONAL_FIELDS = ["intensity", "reflectivity", "timestamp", "offset_time", "tag", "line", "t"]


@st.composite
def well_formed_clouds(draw: st.DrawFn) -> CloudMessage:
    """A consistent PointCloud2 with a random layout and random (partly special) values."""
    names = ["x", "y", "z"] + draw(
        st.lists(st.sampled_from(OPTIONAL_FIELDS), unique=True, max_size=4)
    )
    names = draw(st.permutations(names))
    fields, offset = [], 0
    for name in names:
        datatype = draw(st.sampled_from([7, 7, 8, 1, 2, 3, 4, 5, 6]))
        count = 1 if name in "xyz" else draw(st.sampled_from([1, 1, 1, 2, 3]))
        offset += draw(st.integers(0, 3))
        fields.append(FieldSpec(name, offset, datatype, count))
        offset += struct.calcsize(STRUCT_CODES[datatype]) * count
    point_step = offset + draw(st.integers(0, 8))
    height = draw(st.integers(1, 3))
    width = draw(st.integers(0, 12))
    row_step = width * point_step + draw(st.integers(0, 7))
    data = bytearray(draw(st.binary(min_size=height * row_step, max_size=height * row_step)))
    big = draw(st.booleans())
    order = ">" if big else "<"
    # Overwrite some float coordinates with NaN / Inf / huge / tiny values.
    for spec in fields:
        if spec.name in "xyz" and spec.datatype in (7, 8) and width:
            for _ in range(draw(st.integers(0, 4))):
                row, col = draw(st.integers(0, height - 1)), draw(st.integers(0, width - 1))
                value = draw(st.sampled_from(SPECIAL_FLOATS))
                at = row * row_step + col * point_step + spec.offset
                struct.pack_into(order + STRUCT_CODES[spec.datatype], data, at, value)
    sec = draw(st.integers(0, 2**31 - 1))
    return CloudMessage(
        header=Header(Stamp(sec, draw(st.integers(0, 999_999_999))), "lidar"),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=big,
        point_step=point_step,
        row_step=row_step,
        data=_as_data(bytes(data), draw(st.integers(0, 3))),
    )


def _as_data(raw: bytes, kind: int) -> object:
    """``msg.data`` in the forms the decoder meets: bytes, list, array.array, numpy."""
    import array

    if kind == 0:
        return raw
    if kind == 1:
        return list(raw)
    if kind == 2:
        return array.array("B", raw)
    return np.frombuffer(raw, dtype=np.uint8)


def _reference_xyz(msg: CloudMessage) -> np.ndarray:
    """x, y, z of every point read one by one with ``struct`` (independent of numpy views)."""
    order = ">" if msg.is_bigendian else "<"
    raw = bytes(bytearray(msg.data)) if not isinstance(msg.data, bytes) else msg.data
    by_name = {f.name: f for f in msg.fields}
    rows = []
    for r in range(msg.height):
        for c in range(msg.width):
            base = r * msg.row_step + c * msg.point_step
            point = []
            for axis in "xyz":
                f = by_name[axis]
                (value,) = struct.unpack_from(
                    order + STRUCT_CODES[f.datatype], raw, base + f.offset
                )
                point.append(value)
            rows.append(point)
    with np.errstate(over="ignore", invalid="ignore"):
        return np.array(rows, dtype=np.float64).reshape(-1, 3).astype(np.float32)


@FUZZ
@given(msg=well_formed_clouds())
def _property_pointcloud2_well_formed_layouts_decode_exactly(msg: CloudMessage) -> None:
    _count("pointcloud2 well-formed")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning floods in a node's log either
        decoded = decode_pointcloud2(msg, MID360)
    expected = _reference_xyz(msg)
    finite = np.isfinite(expected).all(axis=1)
    assert isinstance(decoded, DecodedCloud)
    assert decoded.n_points == msg.width * msg.height
    assert decoded.n_dropped_nonfinite == int((~finite).sum())
    frame = decoded.frame
    assert frame.xyz.dtype == np.float32 and frame.xyz.shape == (int(finite.sum()), 3)
    np.testing.assert_array_equal(frame.xyz, expected[finite])
    assert np.isfinite(frame.xyz).all()
    for extra in (frame.intensity, frame.point_time):
        assert extra is None or extra.shape == (len(frame),)
    assert frame.stamp == pytest.approx(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)


def test_pointcloud2_well_formed_report(capsys: pytest.CaptureFixture[str]) -> None:
    _property_pointcloud2_well_formed_layouts_decode_exactly()
    _report(capsys, "pointcloud2 well-formed")
    assert _counts["pointcloud2 well-formed"] >= 100


_NAMES = st.sampled_from(["x", "y", "z", "x", "y", "z", "intensity", "timestamp", "", "é", "a b"])
_BIG = st.sampled_from([2**31, 2**32 + 1, 2**62, 2**63 - 1, -(2**31)])


def _small_or_big(lo: int, hi: int) -> st.SearchStrategy[int]:
    return st.one_of(st.integers(lo, hi), st.integers(lo, hi), _BIG)


@st.composite
def malformed_clouds(draw: st.DrawFn) -> CloudMessage:
    """Anything PointCloud2-shaped: random field tables, sizes and bytes."""
    fields = draw(
        st.lists(
            st.builds(
                FieldSpec,
                _NAMES,
                _small_or_big(-8, 40),
                st.integers(-2, 12),
                _small_or_big(-2, 4),
            ),
            max_size=6,
        )
    )
    if draw(st.booleans()):
        # Start from a consistent xyz cloud and break one size.
        point_step = 12 + draw(st.integers(0, 4))
        fields = [FieldSpec(a, 4 * i, 7) for i, a in enumerate("xyz")] + fields[:2]
        width, height = draw(st.integers(0, 30)), draw(st.integers(0, 3))
        row_step = width * point_step
        n_bytes = height * row_step
        which = draw(st.sampled_from(["point_step", "row_step", "width", "height", "data", "ok"]))
        delta = draw(st.sampled_from([-(2**31), -13, -1, 1, 3, 2**31, 2**40]))
        if which == "point_step":
            point_step += delta
        elif which == "row_step":
            row_step += delta
        elif which == "width":
            width += delta
        elif which == "height":
            height += delta
        elif which == "data":
            n_bytes = max(0, n_bytes + draw(st.integers(-20, 20)))
        data = draw(st.binary(min_size=n_bytes, max_size=n_bytes))
    else:
        point_step = draw(_small_or_big(-4, 48))
        row_step = draw(_small_or_big(-50, 500))
        width, height = draw(_small_or_big(-3, 20)), draw(_small_or_big(-3, 4))
        data = draw(st.binary(max_size=600))
    return CloudMessage(
        header=Header(Stamp(draw(st.integers(0, 2**31 - 1)), 0), ""),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=draw(st.booleans()),
        point_step=point_step,
        row_step=row_step,
        data=data,
    )


_outcomes: dict[str, int] = {}


@FUZZ
@given(msg=malformed_clouds())
def _property_pointcloud2_malformed_raises_only_malformed_cloud_error(msg: CloudMessage) -> None:
    _count("pointcloud2 malformed")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            decoded = decode_pointcloud2(msg, MID360)
    except MalformedCloudError as exc:
        assert str(exc)  # a message naming the problem
        _outcomes["rejected"] = _outcomes.get("rejected", 0) + 1
        return
    _outcomes["decoded"] = _outcomes.get("decoded", 0) + 1
    assert np.isfinite(decoded.frame.xyz).all()
    assert decoded.n_points == msg.width * msg.height


def test_pointcloud2_malformed_report(capsys: pytest.CaptureFixture[str]) -> None:
    _outcomes.clear()
    _property_pointcloud2_malformed_raises_only_malformed_cloud_error()
    _report(
        capsys,
        "pointcloud2 malformed",
        f" ({_outcomes.get('rejected', 0)} rejected with MalformedCloudError, "
        f"{_outcomes.get('decoded', 0)} decodable)",
    )
    assert _outcomes.get("rejected", 0) >= 50


# --------------------------------------------------------------------------- CustomMsg
@st.composite
def custom_msg_frames(draw: st.DrawFn) -> Frame:
    n = draw(st.integers(0, 40))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    xyz = (rng.normal(size=(n, 3)) * 50).astype(np.float32)
    for _ in range(draw(st.integers(0, 3)) if n else 0):
        xyz[draw(st.integers(0, n - 1)), draw(st.integers(0, 2))] = draw(
            st.sampled_from(SPECIAL_FLOATS)
        )
    point_time = np.sort(rng.random(n)) * 0.1 if draw(st.booleans()) else None
    stamp = draw(st.floats(0.0, 2e9)) if draw(st.booleans()) else 1706255621.6
    return Frame(
        stamp,
        MID360,
        xyz,
        intensity=rng.integers(0, 256, n).astype(np.float32),
        point_time=point_time,
    )


@FUZZ
@given(frame=custom_msg_frames(), ros_version=st.sampled_from([1, 2]))
def _property_custom_msg_round_trip_keeps_the_finite_points(frame: Frame, ros_version: int) -> None:
    _count("custommsg well-formed")
    raw = encode_custom_msg(frame, ros_version, frame_id="livox_frame")
    decoded = decode_custom_msg(raw, MID360, ros_version)
    finite = np.isfinite(frame.xyz).all(axis=1)
    assert decoded.n_points == len(frame)
    assert decoded.n_dropped_nonfinite == int((~finite).sum())
    np.testing.assert_array_equal(decoded.frame.xyz, frame.xyz[finite])
    assert np.isfinite(decoded.frame.point_time).all()


def test_custom_msg_round_trip_report(capsys: pytest.CaptureFixture[str]) -> None:
    _property_custom_msg_round_trip_keeps_the_finite_points()
    _report(capsys, "custommsg well-formed")
    assert _counts["custommsg well-formed"] >= 100


@st.composite
def broken_custom_msgs(draw: st.DrawFn) -> tuple[bytes, int]:
    """Valid messages truncated, extended, bit-flipped, with a forged point count, or noise."""
    ros_version = draw(st.sampled_from([1, 2]))
    frame = draw(custom_msg_frames())
    raw = bytearray(encode_custom_msg(frame, ros_version, frame_id=draw(st.text(max_size=8))))
    how = draw(st.sampled_from(["truncate", "flip", "count", "noise", "cdr-header", "extend"]))
    if how == "truncate":
        raw = raw[: draw(st.integers(0, max(len(raw) - 1, 0)))]
    elif how == "extend":
        raw += draw(st.binary(min_size=1, max_size=40))
    elif how == "flip":
        for _ in range(draw(st.integers(1, 8))):
            at = draw(st.integers(0, len(raw) - 1))
            raw[at] ^= 1 << draw(st.integers(0, 7))
    elif how == "count":
        # The points array length sits just before the points; forge it and the string length.
        forged = draw(st.sampled_from([0, 1, 2**16, 2**31 - 1, 2**32 - 1]))
        pos = len(raw) - (len(frame) * (20 if ros_version == 2 else 19) - (ros_version == 2))
        if len(frame) == 0:
            pos = len(raw)
        struct.pack_into("<I", raw, pos - 4, forged)
        string_at = 12  # ROS 1: seq, sec, nsec; ROS 2: encapsulation, sec, nanosec
        if draw(st.booleans()) and len(raw) >= string_at + 4:
            struct.pack_into("<I", raw, string_at, draw(st.sampled_from([0, 7, 2**32 - 1])))
    elif how == "cdr-header":
        raw[:4] = draw(st.binary(min_size=4, max_size=4))
    else:
        prefix = draw(st.sampled_from([b"", b"\x00\x01\x00\x00", b"\x00\x00\x00\x00"]))
        raw = bytearray(prefix + draw(st.binary(max_size=300)))
    return bytes(raw), ros_version


@FUZZ
@given(case=broken_custom_msgs())
def _property_custom_msg_malformed_raises_only_malformed_custom_msg_error(
    case: tuple[bytes, int],
) -> None:
    _count("custommsg malformed")
    raw, ros_version = case
    try:
        decoded = decode_custom_msg(raw, MID360, ros_version)
    except MalformedCustomMsgError as exc:
        assert str(exc)
        _outcomes["cm-rejected"] = _outcomes.get("cm-rejected", 0) + 1
        return
    _outcomes["cm-decoded"] = _outcomes.get("cm-decoded", 0) + 1
    assert np.isfinite(decoded.frame.xyz).all()
    assert decoded.frame.point_time is not None
    assert len(decoded.frame.point_time) == len(decoded.frame)


def test_custom_msg_malformed_report(capsys: pytest.CaptureFixture[str]) -> None:
    _property_custom_msg_malformed_raises_only_malformed_custom_msg_error()
    _report(
        capsys,
        "custommsg malformed",
        f" ({_outcomes.get('cm-rejected', 0)} rejected with MalformedCustomMsgError, "
        f"{_outcomes.get('cm-decoded', 0)} decodable)",
    )
    assert _outcomes.get("cm-rejected", 0) >= 50
